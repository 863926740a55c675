/* Animated render scenes (BART's AFF): the geometry of every keyframed block in a sub-scene of its
 * own, placed by an instance whose transform is the block's at the current time; the still
 * geometry in one more sub-scene under the identity; `tpa` triangles in sub-scenes whose vertices
 * move, so a frame refits them. The top level holds only instances: a frame sets their transforms
 * and rebuilds it (a BVH over a handful of boxes). Sub-scenes keep rest-space geometry (the
 * loader's rest arrays), shading reads the flat world-space arrays of the data, so a hit inside an
 * instance is mapped back to the flat (geom_id, prim_id) it would have in the flat build. */
#include "render.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Group of an element: its innermost block (-1: none) and whether it is a `tpa` triangle. */
static uint32_t group_key(int32_t node, bool tpa) { return (uint32_t)(node + 1) * 2u + (tpa ? 1u : 0u); }

static const float identity_xfm[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};

static void grow(float *lo, float *hi, const float *p, float r) {
    for (int k = 0; k < 3; k++)
        if (isfinite(p[k])) lo[k] = render_fminf(lo[k], p[k] - r), hi[k] = render_fmaxf(hi[k], p[k] + r);
}

static void grow_cone(float *lo, float *hi, const rp_cone_data *c) {
    float r = render_fmaxf(fabsf(c->base_radius), fabsf(c->apex_radius));
    grow(lo, hi, c->base, r);
    grow(lo, hi, c->apex, r);
}

/* The world-space bounds of the data (positions, spheres, cones): animated scenes take their ray
 * offsets from them in both builds, so the flat and the instanced frame agree. What never moves is
 * scanned once; a frame adds the moving vertices, spheres and cones (min and max: the same result
 * as a scan of everything). */
void anim_scene_bounds(rp_render_scene *s) {
    const rp_scene_data *d = s->data;
    const rp_animation_data *a = d->animation;
    if (!s->anim_still_ok) {
        float *lo = s->anim_still, *hi = s->anim_still + 3;
        for (int k = 0; k < 3; k++) lo[k] = INFINITY, hi[k] = -INFINITY;
        uint8_t *moves = calloc(d->vertex_count + 1, 1);
        if (!moves) return;
        for (size_t i = 0; i < a->tpa_count; i++)
            for (uint32_t c = 0; c < 3; c++) moves[a->tpas[i].vertex + c] = 1;
        size_t n = 0;
        for (size_t i = 0; i < d->vertex_count; i++) {
            moves[i] |= a->vertex_node[i] >= 0;
            n += moves[i];
        }
        s->anim_moving = malloc((n + 1) * sizeof *s->anim_moving);
        if (!s->anim_moving) {
            free(moves);
            return;
        }
        for (size_t i = 0; i < d->vertex_count; i++) {
            if (moves[i]) s->anim_moving[s->anim_moving_n++] = (uint32_t)i;
            else grow(lo, hi, d->positions + 3 * i, 0.0f);
        }
        free(moves);
        for (size_t i = 0; i < d->sphere_count; i++)
            if (a->sphere_node[i] < 0) grow(lo, hi, d->spheres[i].center, fabsf(d->spheres[i].radius));
        for (size_t i = 0; i < d->cone_count; i++)
            if (a->cone_node[i] < 0) grow_cone(lo, hi, &d->cones[i]);
        s->anim_still_ok = true;
    }
    float lo[3], hi[3];
    memcpy(lo, s->anim_still, sizeof lo);
    memcpy(hi, s->anim_still + 3, sizeof hi);
    for (size_t j = 0; j < s->anim_moving_n; j++) grow(lo, hi, d->positions + 3 * (size_t)s->anim_moving[j], 0.0f);
    for (size_t i = 0; i < d->sphere_count; i++)
        if (a->sphere_node[i] >= 0) grow(lo, hi, d->spheres[i].center, fabsf(d->spheres[i].radius));
    for (size_t i = 0; i < d->cone_count; i++)
        if (a->cone_node[i] >= 0) grow_cone(lo, hi, &d->cones[i]);
    s->bounds = (rp_bounds){lo[0], lo[1], lo[2], 0.0f, hi[0], hi[1], hi[2], 0.0f};
    const float bv[6] = {lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]};
    float m = 1e-3f;
    for (int k = 0; k < 6; k++)
        if (isfinite(bv[k]) && fabsf(bv[k]) > m) m = fabsf(bv[k]);
    s->scale = m;
    s->extent = bounds_extent(&s->bounds);
}

void anim_groups_free(rp_render_scene *s) {
    for (uint32_t i = 0; i < s->group_count; i++) {
        render_group *g = &s->groups[i];
        if (g->sub) rp_scene_release(g->sub);
        for (int k = 0; k < 3; k++) free(g->map[k]);
        free(g->idx);
        free(g->cones);
    }
    free(s->groups);
    free(s->group_of_top);
    free(s->anim_moving);
    s->anim_moving = NULL;
    s->groups = NULL;
    s->group_count = 0;
}

static uint32_t attach_to(rp_scene *sc, rp_geometry *g) {
    rp_geometry_commit(g);
    uint32_t id = rp_scene_attach(sc, g);
    rp_geometry_release(g);
    return id;
}

/* The transform placing a group: its block's, or the identity (still geometry; world-space blocks). */
static const float *group_xfm(const rp_animation_data *a, const render_group *g) {
    return g->node >= 0 && (!g->deform || g->tpa) ? a->nodes[g->node].xfm : identity_xfm;
}

/* Places a group's instance at xfm, shown when visible. A map with no inverse (a keyframed scale of
 * 0: the block shrunk to nothing) is one rp_geometry_set_instance refuses, which left the instance
 * without a scene and failed the commit ("a geometry lacks a buffer"); the block is hidden instead,
 * where it was (at the identity before its first placement), as the flat build shows nothing of it
 * either. The test is the core's: the 3x3 part's determinant. */
static void group_place(rp_geometry *inst, rp_scene *sub, const float xfm[12], bool placed, bool visible) {
    const float *m = xfm;
    double det = (double)m[0] * ((double)m[5] * m[10] - (double)m[6] * m[9]) +
                 (double)m[1] * ((double)m[6] * m[8] - (double)m[4] * m[10]) +
                 (double)m[2] * ((double)m[4] * m[9] - (double)m[5] * m[8]);
    bool invertible = fabs(det) > 1e-30 && isfinite(det);
    if (invertible || !placed) rp_geometry_set_instance(inst, sub, invertible ? xfm : identity_xfm);
    rp_geometry_set_mask(inst, visible && invertible ? 0xFFFFFFFFu : 0u);
}

/* One group's sub-scene: its triangles (indices into the rest positions), spheres and cones. */
static bool group_build(rp_render_scene *s, const rp_scene_data *d, const rp_render_scene_desc *desc, render_group *g,
                        const uint32_t count[3]) {
    const rp_animation_data *a = d->animation;
    g->sub = rp_scene_new(s->device, &desc->accel);
    if (!g->sub) return false;
    for (int k = 0; k < 3; k++) g->sub_ids[k] = RP_INVALID_ID;
    /* refit_blocks: a block of triangles alone moves its world-space vertices under the identity */
    bool world = desc->refit_blocks && g->node >= 0 && !g->tpa && !count[RENDER_GEOM_SPHERES] && !count[RENDER_GEOM_CONES];
    g->deform = g->tpa || world;
    if (count[RENDER_GEOM_TRIANGLES]) {
        rp_geometry *geo = rp_geometry_new(s->device, RP_GEOMETRY_TRIANGLE);
        if (!geo) return false;
        rp_geometry_set_buffer(geo, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, world ? d->positions : a->rest_positions, 0, 0,
                               d->vertex_count);
        rp_geometry_set_buffer(geo, RP_BUFFER_INDEX, RP_FORMAT_UINT3, g->idx, 0, 0, count[RENDER_GEOM_TRIANGLES]);
        g->tri_geom = geo;
        g->sub_ids[RENDER_GEOM_TRIANGLES] = attach_to(g->sub, geo);
    }
    if (count[RENDER_GEOM_SPHERES]) {
        rp_geometry *geo = rp_geometry_new(s->device, RP_GEOMETRY_SPHERE);
        if (!geo) return false;
        float *v = rp_geometry_new_buffer(geo, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, 0, count[RENDER_GEOM_SPHERES]);
        if (!v) {
            rp_geometry_release(geo);
            return false;
        }
        for (uint32_t i = 0; i < count[RENDER_GEOM_SPHERES]; i++) {
            const rp_sphere_data *sp = &a->rest_spheres[g->map[RENDER_GEOM_SPHERES][i]];
            memcpy(v + 4 * i, sp->center, 3 * sizeof(float));
            v[4 * i + 3] = fabsf(sp->radius);
        }
        g->sub_ids[RENDER_GEOM_SPHERES] = attach_to(g->sub, geo);
    }
    if (count[RENDER_GEOM_CONES]) {
        g->cones = calloc(count[RENDER_GEOM_CONES], sizeof *g->cones);
        if (!g->cones) return false;
        for (uint32_t i = 0; i < count[RENDER_GEOM_CONES]; i++) cone_prepare(&a->rest_cones[g->map[RENDER_GEOM_CONES][i]], &g->cones[i]);
        rp_geometry *geo = rp_geometry_new(s->device, RP_GEOMETRY_USER);
        if (!geo) return false;
        rp_geometry_set_user(geo, count[RENDER_GEOM_CONES], cone_bounds, cone_intersect, cone_occluded, g->cones);
        g->sub_ids[RENDER_GEOM_CONES] = attach_to(g->sub, geo);
    }
    for (int k = 0; k < 3; k++)
        if (count[k] && g->sub_ids[k] == RP_INVALID_ID) return false;
    if (rp_scene_commit(g->sub) != RP_ERROR_NONE) return false;
    rp_geometry *inst = rp_geometry_new(s->device, RP_GEOMETRY_INSTANCE);
    if (!inst) return false;
    group_place(inst, g->sub, group_xfm(a, g), false, g->node < 0 || a->nodes[g->node].visible);
    g->inst = inst;
    g->top_id = attach_to(s->scene, inst);
    return g->top_id != RP_INVALID_ID;
}

bool anim_build_geometry(rp_render_scene *s, const rp_scene_data *d, const rp_render_scene_desc *desc) {
    const rp_animation_data *a = d->animation;
    /* the flat build's geom_ids, so that mapped hits read the same */
    uint32_t id = 0;
    if (d->triangle_count) s->geom_ids[RENDER_GEOM_TRIANGLES] = id++;
    if (d->sphere_count) s->geom_ids[RENDER_GEOM_SPHERES] = id++;
    if (d->cone_count) s->geom_ids[RENDER_GEOM_CONES] = id++;
    size_t keys = 2 * (a->node_count + 1);
    uint32_t (*count)[3] = calloc(keys, sizeof *count);
    uint32_t *slot = malloc(keys * sizeof *slot);
    if (!count || !slot) {
        free(count), free(slot);
        return false;
    }
    for (size_t i = 0; i < d->triangle_count; i++) count[group_key(a->tri_node[i], a->tri_tpa[i])][RENDER_GEOM_TRIANGLES]++;
    for (size_t i = 0; i < d->sphere_count; i++) count[group_key(a->sphere_node[i], false)][RENDER_GEOM_SPHERES]++;
    for (size_t i = 0; i < d->cone_count; i++) count[group_key(a->cone_node[i], false)][RENDER_GEOM_CONES]++;
    uint32_t groups = 0;
    for (size_t k = 0; k < keys; k++) {
        slot[k] = RP_INVALID_ID;
        if (count[k][0] || count[k][1] || count[k][2]) slot[k] = groups++;
    }
    bool ok = false;
    s->groups = calloc(groups + 1, sizeof *s->groups);
    s->group_of_top = malloc((groups + 1) * sizeof *s->group_of_top);
    if (!s->groups || !s->group_of_top) goto done;
    s->group_count = groups;
    for (size_t k = 0; k < keys; k++) {
        if (slot[k] == RP_INVALID_ID) continue;
        render_group *g = &s->groups[slot[k]];
        g->node = (int32_t)(k / 2) - 1;
        g->tpa = (k & 1) != 0;
        g->idx = malloc((3 * (size_t)count[k][0] + 1) * sizeof *g->idx);
        for (int c = 0; c < 3; c++) g->map[c] = malloc(((size_t)count[k][c] + 1) * sizeof *g->map[c]);
        if (!g->idx || !g->map[0] || !g->map[1] || !g->map[2]) goto done;
    }
    uint32_t *fill = calloc((size_t)groups * 3 + 1, sizeof *fill);
    if (!fill) goto done;
    for (size_t i = 0; i < d->triangle_count; i++) {
        uint32_t gi = slot[group_key(a->tri_node[i], a->tri_tpa[i])], j = fill[3 * gi]++;
        render_group *g = &s->groups[gi];
        memcpy(g->idx + 3 * (size_t)j, d->indices + 3 * i, 3 * sizeof(uint32_t));
        g->map[RENDER_GEOM_TRIANGLES][j] = (uint32_t)i;
    }
    for (size_t i = 0; i < d->sphere_count; i++) {
        uint32_t gi = slot[group_key(a->sphere_node[i], false)];
        s->groups[gi].map[RENDER_GEOM_SPHERES][fill[3 * gi + 1]++] = (uint32_t)i;
    }
    for (size_t i = 0; i < d->cone_count; i++) {
        uint32_t gi = slot[group_key(a->cone_node[i], false)];
        s->groups[gi].map[RENDER_GEOM_CONES][fill[3 * gi + 2]++] = (uint32_t)i;
    }
    free(fill);
    for (size_t k = 0; k < keys; k++) {
        if (slot[k] == RP_INVALID_ID) continue;
        render_group *g = &s->groups[slot[k]];
        if (!group_build(s, d, desc, g, count[k])) goto done;
    }
    /* top ids are attach order, one per group; the table maps them back */
    for (uint32_t i = 0; i < groups; i++) s->group_of_top[i] = RP_INVALID_ID;
    for (uint32_t i = 0; i < groups; i++)
        if (s->groups[i].top_id < groups) s->group_of_top[s->groups[i].top_id] = i;
    ok = true;
done:
    free(count);
    free(slot);
    return ok;
}

void scene_hit_flat(const rp_render_scene *s, rp_hit *h) { scene_ids_flat(s, &h->geom_id, &h->prim_id, &h->inst_id); }

/* Lights follow the data (Whitted's and the physically based point and triangle lights). */
static void update_lights(rp_render_scene *s) {
    const rp_scene_data *d = s->data;
    for (size_t i = 0; i < s->light_count && i < d->light_count; i++)
        if (s->lights[i].type == RP_LIGHT_SOURCE_POINT)
            memcpy(s->lights[i].point.position, d->lights[i].position, sizeof d->lights[i].position);
    /* the physically based lights: the data's in its order (light_from_data), among the triangles' */
    size_t point = 0;
    for (size_t k = 0; k < s->pb_light_count; k++) {
        rp_light_source *l = &s->pb_lights[k];
        bool from_data = l->type == RP_LIGHT_SOURCE_POINT || l->type == RP_LIGHT_SOURCE_SPOT ||
                         l->type == RP_LIGHT_SOURCE_DIRECTIONAL;
        if (from_data && point < d->light_count) {
            const rp_light_data *ld = &d->lights[point++];
            if (l->type == RP_LIGHT_SOURCE_POINT) memcpy(l->point.position, ld->position, sizeof l->point.position);
            if (l->type == RP_LIGHT_SOURCE_SPOT) memcpy(l->spot.position, ld->position, sizeof l->spot.position);
        } else if (l->type == RP_LIGHT_SOURCE_TRIANGLE && l->triangle.prim < d->triangle_count) {
            for (int c = 0; c < 3; c++)
                memcpy(l->triangle.p[c], d->positions + 3 * (size_t)d->indices[3 * (size_t)l->triangle.prim + (size_t)c],
                       3 * sizeof(float));
        }
    }
}

static void count_commit(rp_scene *sc, rp_render_update_stats *st) {
    rp_scene_stats ss;
    rp_scene_get_stats(sc, &ss);
    if (ss.refit) st->refits++;
    else st->rebuilds++;
}

bool rp_render_scene_set_time(rp_render_scene *s, rp_scene_data *data, float time, rp_render_update_stats *stats) {
    rp_render_update_stats st;
    memset(&st, 0, sizeof st);
    if (stats) *stats = st;
    if (!s || !data || data != s->data || !data->animation) return false;
    double t0 = now_ms();
    if (!rp_scene_data_set_time(data, time)) return false;
    double t1 = now_ms();
    st.eval_ms = t1 - t0;
    const rp_animation_data *a = data->animation;
    bool ok = true;
    if (s->groups) {
        for (uint32_t i = 0; i < s->group_count; i++) {
            render_group *g = &s->groups[i];
            if (g->deform && g->tri_geom) {
                rp_geometry_update(g->tri_geom, RP_BUFFER_VERTEX);
                double r0 = now_ms();
                ok = ok && rp_scene_commit(g->sub) == RP_ERROR_NONE;
                st.refit_ms += now_ms() - r0;
                count_commit(g->sub, &st);
                group_place(g->inst, g->sub, group_xfm(a, g), true, g->node < 0 || a->nodes[g->node].visible);
                st.instances++;
            } else if (g->node >= 0) {
                group_place(g->inst, g->sub, a->nodes[g->node].xfm, true, a->nodes[g->node].visible);
                st.instances++;
            }
        }
        double r0 = now_ms();
        ok = ok && rp_scene_commit(s->scene) == RP_ERROR_NONE;
        st.top_ms = now_ms() - r0;
        count_commit(s->scene, &st);
    } else {
        /* the flat build: every moved vertex in the one triangle structure (a refit), spheres and
         * cones copied again */
        const rp_scene_data *d = data;
        rp_geometry *g = s->geom_ids[RENDER_GEOM_TRIANGLES] != RP_INVALID_ID ? rp_scene_get_geometry(s->scene, s->geom_ids[RENDER_GEOM_TRIANGLES]) : NULL;
        if (g) rp_geometry_update(g, RP_BUFFER_VERTEX);
        g = s->geom_ids[RENDER_GEOM_SPHERES] != RP_INVALID_ID ? rp_scene_get_geometry(s->scene, s->geom_ids[RENDER_GEOM_SPHERES]) : NULL;
        if (g) {
            float *v = rp_geometry_new_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, 0, d->sphere_count);
            if (!v) ok = false;
            for (size_t i = 0; v && i < d->sphere_count; i++) {
                memcpy(v + 4 * i, d->spheres[i].center, 3 * sizeof(float));
                v[4 * i + 3] = fabsf(d->spheres[i].radius);
            }
            rp_geometry_commit(g);
        }
        g = s->geom_ids[RENDER_GEOM_CONES] != RP_INVALID_ID ? rp_scene_get_geometry(s->scene, s->geom_ids[RENDER_GEOM_CONES]) : NULL;
        if (g) {
            for (size_t i = 0; i < d->cone_count; i++) cone_prepare(&d->cones[i], &s->cones[i]);
            rp_geometry_update(g, RP_BUFFER_VERTEX);
        }
        double r0 = now_ms();
        ok = ok && rp_scene_commit(s->scene) == RP_ERROR_NONE;
        st.refit_ms = now_ms() - r0;
        count_commit(s->scene, &st);
    }
    update_lights(s);
    anim_scene_bounds(s);
    st.update_ms = now_ms() - t0;
    if (stats) *stats = st;
    return ok;
}
