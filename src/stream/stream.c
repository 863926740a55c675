/* The multipass stream tracer (Purcell et al. 2002). See stream.h. */
#include "stream/stream.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "render/render.h"
#include "sys/sys.h"

const stream_paper_row stream_paper_table2[] = {
    {"Soda Hall Outside", 2443, 692, 1747, 4, 384, 1123, 0.009},
    {"Soda Hall Inside", 1198, 70, 1124, 4, 60, 1039, 0.061},
    {"Forest Top Down", 1999, 311, 1684, 4, 137, 1435, 0.062},
    {"Forest Inside", 2835, 1363, 1468, 4, 898, 990, 0.068},
    {"Bunny Ray Cast", 1085, 610, 471, 4, 221, 328, 0.105},
};
const size_t stream_paper_table2_count = sizeof stream_paper_table2 / sizeof stream_paper_table2[0];

stream_desc stream_desc_defaults(const stream_desc *desc) {
    stream_desc d = desc ? *desc : (stream_desc){0};
    if (d.width <= 0) d.width = 512;
    if (d.height <= 0) d.height = 512;
    if (!(d.oracle > 0.0f)) d.oracle = 0.2f;
    return d;
}

/* The per-ray state of the paper's state machine. */
typedef enum ray_state { RAY_TRAVERSING = 0, RAY_INTERSECTING = 1, RAY_SHADING = 2, RAY_DONE = 3 } ray_state;

/* A stream of rays, structure of arrays: one entry per ray in each. */
typedef struct ray_stream {
    size_t count;
    bool any;              /* shadow rays: stop at the first hit */
    rp_ray *ray;
    grid_walk *walk;       /* traversal state: voxel and stepping */
    grid_hit *hit;         /* closest hit so far */
    uint32_t *cursor, *end;/* the voxel's triangle list still to test */
    uint32_t *mailbox;     /* GRID_MAILBOX per ray */
    uint8_t *state;
    uint32_t *voxels, *tests;
    uint32_t *active;      /* rays traversing or intersecting, compacted after each pass */
    uint32_t *queue;       /* wavefront: the intersect queue, then the traverse queue (2 per ray) */
    size_t active_count;
} ray_stream;

static void stream_free(ray_stream *s) {
    free(s->ray), free(s->walk), free(s->hit), free(s->cursor), free(s->end), free(s->mailbox);
    free(s->state), free(s->voxels), free(s->tests), free(s->active), free(s->queue);
    memset(s, 0, sizeof *s);
}

static bool stream_alloc(ray_stream *s, size_t n, bool any) {
    memset(s, 0, sizeof *s);
    s->count = n, s->any = any;
    size_t m = n ? n : 1;
    s->ray = malloc(m * sizeof(rp_ray));
    s->walk = malloc(m * sizeof(grid_walk));
    s->hit = malloc(m * sizeof(grid_hit));
    s->cursor = malloc(m * sizeof(uint32_t));
    s->end = malloc(m * sizeof(uint32_t));
    s->mailbox = malloc(m * GRID_MAILBOX * sizeof(uint32_t));
    s->state = malloc(m);
    s->voxels = calloc(m, sizeof(uint32_t));
    s->tests = calloc(m, sizeof(uint32_t));
    s->active = malloc(m * sizeof(uint32_t));
    s->queue = malloc(2 * m * sizeof(uint32_t));
    if (!s->queue || !s->ray || !s->walk || !s->hit || !s->cursor || !s->end || !s->mailbox || !s->state || !s->voxels ||
        !s->tests || !s->active) {
        stream_free(s);
        return false;
    }
    return true;
}

/* Enters voxel state: intersecting when the current voxel lists triangles, else traversing. */
static void enter_voxel(const grid *g, ray_stream *s, uint32_t i) {
    uint32_t c = grid_walk_voxel(g, &s->walk[i]);
    s->voxels[i]++;
    s->cursor[i] = g->offsets[c], s->end[i] = g->offsets[c + 1];
    s->state[i] = s->cursor[i] < s->end[i] ? RAY_INTERSECTING : RAY_TRAVERSING;
}

/* Kernel: traversal setup (per-ray DDA setup and the first voxel). */
static void kernel_setup(const grid *g, ray_stream *s) {
    s->active_count = 0;
    for (size_t i = 0; i < s->count; i++) {
        s->hit[i] = (grid_hit){.t = s->ray[i].tfar, .tri = UINT32_MAX};
        for (int k = 0; k < GRID_MAILBOX; k++) s->mailbox[i * GRID_MAILBOX + k] = UINT32_MAX;
        if (!(s->ray[i].tnear <= s->ray[i].tfar) || !grid_walk_setup(g, &s->ray[i], &s->walk[i])) {
            s->state[i] = RAY_SHADING; /* misses the grid: shaded as a miss */
            continue;
        }
        enter_voxel(g, s, (uint32_t)i);
        s->active[s->active_count++] = (uint32_t)i;
    }
}

/* Kernel: one traversal step of ray i (a traversal pass runs it on every traversing ray). */
static void kernel_traverse(const grid *g, ray_stream *s, uint32_t i) {
    if (!grid_walk_step(g, &s->walk[i], s->hit[i].t))
        s->state[i] = RAY_SHADING;
    else
        enter_voxel(g, s, i);
}

/* Kernel: one triangle of ray i's voxel list (triangles already in its mailbox are passed over).
 * At the end of the list the ray is done when its closest hit lies within the voxel. */
static void kernel_intersect(const grid *g, ray_stream *s, uint32_t i) {
    uint32_t *mb = &s->mailbox[(size_t)i * GRID_MAILBOX];
    while (s->cursor[i] < s->end[i]) {
        uint32_t tri = g->items[s->cursor[i]++];
        if (grid_mailbox_seen(mb, tri)) continue;
        s->tests[i]++;
        if (grid_test(g, tri, &s->ray[i], &s->hit[i]) && s->any) {
            s->state[i] = RAY_SHADING;
            return;
        }
        break;
    }
    if (s->cursor[i] < s->end[i]) return;
    const grid_walk *w = &s->walk[i];
    float end = s->hit[i].t < w->t_end ? s->hit[i].t : w->t_end;
    s->state[i] = grid_walk_exit(g, w) < end ? RAY_TRAVERSING : RAY_SHADING;
}

/* The wavefront loop (Laine, Karras, Aila 2013): every iteration compacts the active rays into one
 * queue per kernel and runs both kernels, each over its own queue only, so every ray of a pass
 * does work (SIMD efficiency 1 by construction; the cost moves into the compaction). */
static void run_wavefront(const grid *g, ray_stream *s, stream_stats *st) {
    uint32_t *qi = s->queue, *qt = s->queue + (s->count ? s->count : 1);
    for (;;) {
        size_t ni = 0, nt = 0;
        for (size_t k = 0; k < s->active_count; k++) {
            uint32_t i = s->active[k];
            if (s->state[i] == RAY_INTERSECTING) qi[ni++] = i;
            else qt[nt++] = i;
        }
        if (ni + nt == 0) break;
        if (ni) {
            for (size_t k = 0; k < ni; k++) kernel_intersect(g, s, qi[k]);
            st->intersection_passes++, st->work += ni, st->slots += ni;
        }
        if (nt) {
            for (size_t k = 0; k < nt; k++) kernel_traverse(g, s, qt[k]);
            st->traversal_passes++, st->work += nt, st->slots += nt;
        }
        size_t kept = 0;
        for (size_t k = 0; k < s->active_count; k++) {
            uint32_t i = s->active[k];
            if (s->state[i] == RAY_TRAVERSING || s->state[i] == RAY_INTERSECTING) s->active[kept++] = i;
        }
        s->active_count = kept;
    }
}

/* The multipass loop: the oracle picks the pass, the pass runs its kernel on the rays in its state
 * (the others wait, as fragments killed by the stencil do). */
static void run_passes(const grid *g, ray_stream *s, float oracle, bool wavefront, stream_stats *st) {
    kernel_setup(g, s);
    st->other_passes++;
    for (;;) {
        if (wavefront) {
            run_wavefront(g, s, st);
            break;
        }
        size_t n_trav = 0, n_isect = 0;
        for (size_t k = 0; k < s->active_count; k++) {
            uint8_t q = s->state[s->active[k]];
            n_trav += q == RAY_TRAVERSING, n_isect += q == RAY_INTERSECTING;
        }
        if (n_trav + n_isect == 0) break;
        bool isect = n_isect > 0 && (float)n_isect >= oracle * (float)(n_trav + n_isect);
        uint8_t want = isect ? RAY_INTERSECTING : RAY_TRAVERSING;
        size_t kept = 0, worked = 0;
        for (size_t k = 0; k < s->active_count; k++) {
            uint32_t i = s->active[k];
            if (s->state[i] == want) {
                worked++;
                if (isect)
                    kernel_intersect(g, s, i);
                else
                    kernel_traverse(g, s, i);
            }
            if (s->state[i] == RAY_TRAVERSING || s->state[i] == RAY_INTERSECTING) s->active[kept++] = i;
        }
        s->active_count = kept;
        if (isect)
            st->intersection_passes++;
        else
            st->traversal_passes++;
        st->work += worked;
        st->slots += s->count;
    }
    for (size_t i = 0; i < s->count; i++) {
        st->voxels += s->voxels[i], st->tests += s->tests[i];
        if (s->voxels[i] > st->max_voxels) st->max_voxels = s->voxels[i];
        if (s->tests[i] > st->max_tests) st->max_tests = s->tests[i];
    }
    st->rays += s->count;
}

static void hit_of(const grid *g, const ray_stream *s, size_t i, rp_rayhit *rh) {
    rh->ray = s->ray[i];
    rh->hit = (rp_hit){.geom_id = RP_INVALID_ID, .prim_id = RP_INVALID_ID, .inst_id = RP_INVALID_ID};
    grid_hit_write(g, &s->hit[i], rh);
}

/* The eyelight integrator's shade (render.c, shade_primary), the same arithmetic. */
static float eyelight(const rp_rayhit *rh) {
    if (rh->hit.geom_id == RP_INVALID_ID) return 0.0f;
    v3 ng = v3_normalize(v3_make(rh->hit.Ng_x, rh->hit.Ng_y, rh->hit.Ng_z));
    float c = fabsf(v3_dot(ng, v3_make(rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z)));
    if (!(c <= 1.0f)) c = c > 1.0f ? 1.0f : 0.0f;
    return c;
}

bool stream_render(rp_render_scene *rs, const grid *g, const stream_desc *desc_in, float *pixels, rp_rayhit *hits,
                   stream_stats *stats, char *err, size_t err_size) {
    double t0 = sys_seconds();
    stream_desc d = stream_desc_defaults(desc_in);
    stream_stats st = {0};
    if (!rs || !g || !pixels) {
        snprintf(err, err_size, "stream: missing scene, grid or pixels");
        return false;
    }
    size_t n = (size_t)d.width * (size_t)d.height;
    ray_stream eye;
    if (!stream_alloc(&eye, n, false)) {
        snprintf(err, err_size, "stream: out of memory for %zu rays", n);
        return false;
    }
    /* Kernel: eye-ray generation, the renderer's camera (pixel centres) */
    rp_camera cam = d.camera ? *d.camera : rp_render_scene_default_camera(rs);
    render_camera rc;
    camera_setup(&cam, d.width, d.height, &rc);
    for (size_t i = 0; i < n; i++)
        camera_ray(&rc, (float)(i % (size_t)d.width) + 0.5f, (float)(i / (size_t)d.width) + 0.5f, &eye.ray[i]);
    st.other_passes++;
    run_passes(g, &eye, d.oracle, d.wavefront, &st);
    st.eye_rays = n;

    /* Kernel: shading (one pass); with shadows it emits the shadow stream */
    ray_stream shadow = {0};
    bool shadows = d.shading == STREAM_SHADE_SHADOW;
    v3 light = rc.eye;
    if (shadows && rs->light_count > 0 && rs->lights[0].type == RP_LIGHT_SOURCE_POINT)
        light = v3_load(rs->lights[0].point.position);
    if (shadows && !stream_alloc(&shadow, n, true)) {
        stream_free(&eye);
        snprintf(err, err_size, "stream: out of memory for %zu shadow rays", n);
        return false;
    }
    float *kd_cos = shadows ? malloc(n * 3 * sizeof(float)) : NULL;
    if (shadows && !kd_cos) {
        stream_free(&eye), stream_free(&shadow);
        snprintf(err, err_size, "stream: out of memory");
        return false;
    }
    float eps = 2e-5f * rs->scale;
    for (size_t i = 0; i < n; i++) {
        rp_rayhit rh;
        hit_of(g, &eye, i, &rh);
        if (hits) hits[i] = rh;
        bool hit = rh.hit.geom_id != RP_INVALID_ID;
        st.eye_hits += hit, st.shades += hit;
        eye.state[i] = RAY_DONE;
        if (!shadows) {
            float c = eyelight(&rh);
            pixels[3 * i + 0] = c, pixels[3 * i + 1] = c, pixels[3 * i + 2] = c;
            continue;
        }
        rp_ray *sr = &shadow.ray[i];
        render_ray_init(sr, rc.eye, v3_make(0, 0, 1), -1.0f); /* a miss: nothing to trace */
        if (!hit) {
            for (int k = 0; k < 3; k++) kd_cos[3 * i + k] = 0.0f;
            continue;
        }
        render_surface sf;
        scene_surface(rs, &rh.ray, &rh.hit, &sf);
        v3 kd = material_albedo(rs, &rs->materials[sf.material], &sf);
        v3 org = v3_madd(sf.p, sf.ng, eps), to = v3_sub(light, org);
        float dist = v3_length(to);
        v3 l = dist > 0.0f ? v3_scale(to, 1.0f / dist) : sf.ng;
        float c = v3_dot(sf.ns, l);
        c = c > 0.0f ? c : 0.0f;
        kd_cos[3 * i + 0] = kd.x * c, kd_cos[3 * i + 1] = kd.y * c, kd_cos[3 * i + 2] = kd.z * c;
        for (int k = 0; k < 3; k++) pixels[3 * i + k] = 0.1f * v3_at(kd, k);
        if (c > 0.0f) render_ray_init(sr, org, l, dist * (1.0f - 1e-4f));
    }
    st.other_passes++;
    if (shadows) {
        run_passes(g, &shadow, d.oracle, d.wavefront, &st);
        for (size_t i = 0; i < n; i++) {
            bool traced = shadow.ray[i].tfar >= 0.0f;
            if (!traced) continue;
            st.shadow_rays++;
            bool blocked = shadow.hit[i].tri != UINT32_MAX;
            st.shadow_blocked += blocked;
            st.shades++;
            if (!blocked)
                for (int k = 0; k < 3; k++) pixels[3 * i + k] += 0.9f * kd_cos[3 * i + k];
        }
        st.other_passes++; /* the final shading pass */
        /* shadow rays that were not traced (misses, back-lit) are not rays of the frame */
        st.rays -= n - st.shadow_rays;
        free(kd_cos);
        stream_free(&shadow);
    }
    stream_free(&eye);
    st.passes = st.traversal_passes + st.intersection_passes + st.other_passes;
    st.simd_efficiency = st.slots ? (double)st.work / (double)st.slots : 0.0;
    st.ms = (sys_seconds() - t0) * 1e3;
    if (stats) *stats = st;
    return true;
}
