/* What the physically based integrators share: their per-thread buffers, per-frame state, the MIS
 * weight and the packet queries. */
#include "pbr.h"

#include <stdlib.h>
#include <string.h>

float pbr_mis(float a, float b) {
    /* The power heuristic (Veach 1997), beta = 2. */
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

rp_query_n_desc pbr_query(const render_frame *f, render_thread *th, rp_ray_kind kind) {
    rp_query_n_desc q = {.traversal = f->traversal[kind],
                         .counters = th->work ? &th->work[kind] : NULL,
                         .tally = &th->pbr->tally[kind]};
    q.frustum = f->desc.no_frustum ? RP_FRUSTUM_NONE : (kind == RP_RAY_SHADOW ? RP_FRUSTUM_SHADOW : RP_FRUSTUM_PRIMARY);
    return q;
}

uint32_t pbr_tile_side(const rp_render_desc *d) {
    if (d->integrator == RP_INTEGRATOR_IR) {
        uint32_t n = (uint32_t)(d->ir.interleave > 0 ? d->ir.interleave : 5);
        return n * 8u;
    }
    uint32_t n = (uint32_t)d->packet, ts = (uint32_t)d->tile_size;
    return (ts < n ? n : ts + n - 1) / n * n;
}

bool pbr_frame_init(render_frame *f) {
    f->pbr = calloc(1, sizeof *f->pbr);
    if (!f->pbr) return false;
    if (f->desc.integrator == RP_INTEGRATOR_IR) return ir_frame_init(f);
    return true;
}

void pbr_frame_free(render_frame *f) {
    pbr_frame *pf = f->pbr;
    if (!pf) return;
    free(pf->vpls);
    render_scratch_give(f->s, pf->planes);
    free(pf);
    f->pbr = NULL;
}

bool pbr_thread_init(const render_frame *f, render_thread *th) {
    pbr_thread *pt = calloc(1, sizeof *pt);
    if (!pt) return false;
    th->pbr = pt;
    size_t nn = (size_t)f->tile * f->tile;
    bool ir = f->desc.integrator == RP_INTEGRATOR_IR;
    uint32_t side = ir ? 8u : (uint32_t)f->desc.packet;
    for (uint32_t j = 0; j < side; j++)
        for (uint32_t i = 0; i < side; i++) pt->lane[j * side + i] = rp_packet_n_index(side, i, j);
    pt->prim_valid = calloc((size_t)side * side, sizeof *pt->prim_valid);
    pt->paths = calloc(nn, sizeof *pt->paths);
    pt->bounce = aligned_alloc(64, (nn * sizeof *pt->bounce + 63u) & ~(size_t)63u);
    pt->shadow = aligned_alloc(64, (nn * sizeof *pt->shadow + 63u) & ~(size_t)63u);
    pt->shadow_L = calloc(nn, sizeof *pt->shadow_L);
    pt->shadow_pixel = calloc(nn, sizeof *pt->shadow_pixel);
    if (f->desc.count_work) th->work = calloc(RP_RAY_KIND_COUNT, sizeof *th->work);
    bool ok = pt->prim_valid && pt->paths && pt->bounce && pt->shadow && pt->shadow_L && pt->shadow_pixel &&
              (!f->desc.count_work || th->work) && rp_rayhit_n_alloc(f->s->device, side, &pt->prim);
    if (ok && ir) {
        pt->points = calloc(nn, sizeof *pt->points);
        pt->ir_sum = calloc(nn, sizeof *pt->ir_sum);
        pt->ir_at = calloc(nn, sizeof *pt->ir_at); /* (tile / N)^2 blocks of N^2 sets */
        pt->chunk = aligned_alloc(64, (sizeof *pt->chunk + 63u) & ~(size_t)63u);
        ok = pt->points && pt->ir_sum && pt->ir_at && pt->chunk && rp_rayhit_n_alloc(f->s->device, side, &pt->vpl_packet) &&
             rp_rayhit_n_alloc(f->s->device, 32, &pt->rr_packet);
    }
    return ok;
}

void pbr_thread_free(const render_frame *f, render_thread *th) {
    pbr_thread *pt = th->pbr;
    if (!pt) return;
    if (pt->prim.n) rp_rayhit_n_free(f->s->device, &pt->prim);
    if (pt->vpl_packet.n) rp_rayhit_n_free(f->s->device, &pt->vpl_packet);
    if (pt->rr_packet.org_x) {
        pt->rr_packet.n = 32; /* ir_tile sizes it to its rays */
        rp_rayhit_n_free(f->s->device, &pt->rr_packet);
    }
    free(pt->prim_valid);
    free(pt->paths);
    free(pt->bounce);
    free(pt->shadow);
    free(pt->shadow_L);
    free(pt->shadow_pixel);
    free(pt->points);
    free(pt->ir_sum);
    free(pt->ir_at);
    free(pt->chunk);
    free(pt);
    th->pbr = NULL;
}

bool pbr_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1) {
    /* What auto traversal learns starts afresh per tile, so that the way each packet is traced (and
     * any difference between the ways at an edge) does not depend on which thread had which tiles. */
    memset(th->pbr->tally, 0, sizeof th->pbr->tally);
    if (f->desc.integrator == RP_INTEGRATOR_IR) return ir_tile(f, th, x0, y0, x1, y1);
    return path_tile(f, th, x0, y0, x1, y1);
}

void pbr_frame_finish(render_frame *f) {
    if (f->desc.integrator == RP_INTEGRATOR_IR) ir_frame_finish(f);
}
