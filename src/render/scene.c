/* Render scene: core geometries from the loaders' flat data, materials, lights, shading points. */
#include "medium.h"
#include "render.h"

#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

rp_render_scene_desc rp_render_scene_desc_defaults(const rp_render_scene_desc *desc) {
    rp_render_scene_desc d;
    memset(&d, 0, sizeof d);
    if (desc) d = *desc;
    d.accel = rp_scene_desc_defaults(&d.accel);
    if (d.medium.density_scale == 0.0f) d.medium.density_scale = 1.0f;
    if (d.medium.albedo[0] == 0.0f && d.medium.albedo[1] == 0.0f && d.medium.albedo[2] == 0.0f)
        d.medium.albedo[0] = d.medium.albedo[1] = d.medium.albedo[2] = 1.0f;
    return d;
}

static float srgb_decode(float c) {
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

struct render_scratch {
    _Atomic(void *) block; /* a render_block, or NULL */
};

/* A scratch block's header; the caller's bytes follow it, 64-byte aligned. */
typedef struct render_block {
    size_t bytes; /* usable after the header */
    _Alignas(64) unsigned char data[];
} render_block;

void *render_scratch_take(const rp_render_scene *s, size_t bytes) {
    render_block *b = s && s->scratch ? atomic_exchange(&s->scratch->block, NULL) : NULL;
    if (b && b->bytes < bytes) {
        free(b);
        b = NULL;
    }
    if (!b) {
        /* From 1 MiB on whole 2 MiB pages, where the kernel gives them: a first frame faults a
         * few huge pages instead of thousands of small ones. */
        const size_t huge = (size_t)2 << 20;
        size_t total = sizeof(render_block) + bytes, align = 64;
        if (total < bytes) return NULL;
        if (total >= ((size_t)1 << 20)) {
            align = huge;
            total = (total + huge - 1) / huge * huge;
        } else {
            total = (total + 63u) & ~(size_t)63u;
        }
        b = aligned_alloc(align, total);
        if (!b) return NULL;
#ifdef MADV_HUGEPAGE
        if (align == huge) madvise(b, total, MADV_HUGEPAGE);
#endif
        b->bytes = total - sizeof(render_block);
    }
    memset(b->data, 0, bytes);
    return b->data;
}

void render_scratch_give(const rp_render_scene *s, void *block) {
    if (!block) return;
    render_block *b = (render_block *)((unsigned char *)block - offsetof(render_block, data));
    if (!s || !s->scratch) {
        free(b);
        return;
    }
    free(atomic_exchange(&s->scratch->block, b));
}

static void scene_free(rp_render_scene *s) {
    if (!s) return;
    if (s->scratch) free(atomic_load(&s->scratch->block));
    free(s->scratch);
    if (s->scene) rp_scene_release(s->scene);
    anim_groups_free(s); /* after the top scene, whose instances hold the sub-scenes */
    if (s->device) rp_device_release(s->device);
    free(s->materials);
    free(s->material_ke);
    free(s->lights);
    free(s->cones);
    light_scene_free(s);
    medium_free(s->medium);
    free(s->medium);
    free(s);
}

/* Frees a half-built scene and reports why; returns NULL for the caller to return. */
static rp_render_scene *fail(rp_render_scene *s, char *err, size_t err_size, const char *msg) {
    if (err && err_size) snprintf(err, err_size, "%s", msg);
    scene_free(s);
    return NULL;
}

/* Attaches a geometry, committing it first; returns its geom_id or RP_INVALID_ID. */
static uint32_t attach(rp_render_scene *s, rp_geometry *g) {
    rp_geometry_commit(g);
    uint32_t id = rp_scene_attach(s->scene, g);
    rp_geometry_release(g);
    return id;
}

static bool build_geometry(rp_render_scene *s, const rp_scene_data *d) {
    if (d->triangle_count > 0) {
        rp_geometry *g = rp_geometry_new(s->device, RP_GEOMETRY_TRIANGLE);
        if (!g) return false;
        rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, d->positions, 0, 0, d->vertex_count);
        rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, d->indices, 0, 0, d->triangle_count);
        s->geom_ids[RENDER_GEOM_TRIANGLES] = attach(s, g);
        if (s->geom_ids[RENDER_GEOM_TRIANGLES] == RP_INVALID_ID) return false;
    }
    if (d->sphere_count > 0) {
        rp_geometry *g = rp_geometry_new(s->device, RP_GEOMETRY_SPHERE);
        if (!g) return false;
        float *v = rp_geometry_new_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, 0, d->sphere_count);
        if (!v) {
            rp_geometry_release(g);
            return false;
        }
        for (size_t i = 0; i < d->sphere_count; i++) {
            memcpy(v + 4 * i, d->spheres[i].center, 3 * sizeof(float));
            v[4 * i + 3] = fabsf(d->spheres[i].radius);
        }
        s->geom_ids[RENDER_GEOM_SPHERES] = attach(s, g);
        if (s->geom_ids[RENDER_GEOM_SPHERES] == RP_INVALID_ID) return false;
    }
    if (d->cone_count > 0) {
        s->cones = calloc(d->cone_count, sizeof *s->cones);
        if (!s->cones) return false;
        for (size_t i = 0; i < d->cone_count; i++) cone_prepare(&d->cones[i], &s->cones[i]);
        rp_geometry *g = rp_geometry_new(s->device, RP_GEOMETRY_USER);
        if (!g) return false;
        rp_geometry_set_user(g, (uint32_t)d->cone_count, cone_bounds, cone_intersect, cone_occluded, s->cones);
        s->geom_ids[RENDER_GEOM_CONES] = attach(s, g);
        if (s->geom_ids[RENDER_GEOM_CONES] == RP_INVALID_ID) return false;
    }
    return true;
}

rp_render_scene *rp_render_scene_new(rp_device *device, const rp_scene_data *data,
                                     const rp_render_scene_desc *desc, char *err, size_t err_size) {
    if (!device || !data) {
        return fail(NULL, err, err_size, "rp_render_scene_new: no device or no scene data");
    }
    rp_render_scene_desc dd = rp_render_scene_desc_defaults(desc);
    rp_render_scene *s = calloc(1, sizeof *s);
    if (!s) return fail(NULL, err, err_size, "out of memory");
    s->scratch = calloc(1, sizeof *s->scratch);
    if (!s->scratch) return fail(s, err, err_size, "out of memory");
    atomic_init(&s->scratch->block, NULL);
    rp_device_retain(device);
    s->device = device;
    s->data = data;
    for (int k = 0; k < 3; k++) s->geom_ids[k] = RP_INVALID_ID;
    for (int i = 0; i < 256; i++) s->srgb_to_linear[i] = srgb_decode((float)i / 255.0f);

    size_t nm = data->material_count > 0 ? data->material_count : 1;
    s->materials = calloc(nm, sizeof *s->materials);
    if (!s->materials) return fail(s, err, err_size, "out of memory");
    for (size_t i = 0; i < data->material_count; i++) s->materials[i] = rp_material_from_data(&data->materials[i]);
    if (data->material_count == 0) {
        s->materials[0] = (rp_material){.type = RP_MATERIAL_DIFFUSE, .kd = {0.8f, 0.8f, 0.8f}, .texture = -1,
                                        .roughness_texture = -1, .normal_texture = -1,
                                        .emission_texture = -1, .alpha = 1.0f, .alpha_texture = -1,
                                        .specular_texture = -1};
    }

    s->material_ke = malloc(nm * sizeof *s->material_ke);
    if (!s->material_ke) return fail(s, err, err_size, "out of memory");
    for (size_t i = 0; i < data->material_count; i++) s->material_ke[i] = material_ke_compute(s, (uint32_t)i);
    s->material_ke_count = data->material_count;

    s->cutouts = alpha_scene_has_cutouts(s);

    s->light_count = data->light_count;
    if (s->light_count) {
        s->lights = calloc(s->light_count, sizeof *s->lights);
        if (!s->lights) return fail(s, err, err_size, "out of memory");
    }
    for (size_t i = 0; i < s->light_count; i++) {
        const rp_light_data *l = &data->lights[i];
        switch (l->type) {
        case RP_LIGHT_DATA_POINT:
            s->lights[i].type = RP_LIGHT_SOURCE_POINT;
            memcpy(s->lights[i].point.position, l->position, sizeof l->position);
            memcpy(s->lights[i].point.intensity, l->color, sizeof l->color);
            s->lights[i].point.inverse_square = false;
            break;
        case RP_LIGHT_DATA_SPOT:
        case RP_LIGHT_DATA_DIRECTIONAL:
            light_from_data(l, &s->lights[i]); /* Whitted passes them by (it sees point lights) */
            break;
        }
    }

    s->scene = rp_scene_new(device, &dd.accel);
    if (!s->scene) return fail(s, err, err_size, "cannot create a scene (out of memory)");
    bool instanced = data->animation && !dd.flatten_animation;
    if (!(instanced ? anim_build_geometry(s, data, &dd) : build_geometry(s, data))) {
        char msg[160];
        snprintf(msg, sizeof msg, "cannot create the scene's geometry: %s", rp_error_string(rp_device_get_error(device)));
        return fail(s, err, err_size, msg);
    }
    rp_error e = rp_scene_commit(s->scene);
    if (e != RP_ERROR_NONE) {
        char msg[160];
        snprintf(msg, sizeof msg, "scene commit failed: %s", rp_error_string(e));
        return fail(s, err, err_size, msg);
    }
    rp_scene_get_bounds(s->scene, &s->bounds);
    if (data->volume) {
        s->medium = malloc(sizeof *s->medium);
        if (!s->medium || !medium_init(s->medium, data->volume, &dd.medium)) return fail(s, err, err_size, "out of memory");
        /* the scene's box holds the medium's: framing, ray offsets and the environment's power */
        const rp_bounds *mb = &s->medium->bounds;
        rp_bounds *sb = &s->bounds;
        bool none = !(sb->lower_x <= sb->upper_x && sb->lower_y <= sb->upper_y && sb->lower_z <= sb->upper_z);
        sb->lower_x = none ? mb->lower_x : render_fminf(sb->lower_x, mb->lower_x);
        sb->lower_y = none ? mb->lower_y : render_fminf(sb->lower_y, mb->lower_y);
        sb->lower_z = none ? mb->lower_z : render_fminf(sb->lower_z, mb->lower_z);
        sb->upper_x = none ? mb->upper_x : render_fmaxf(sb->upper_x, mb->upper_x);
        sb->upper_y = none ? mb->upper_y : render_fmaxf(sb->upper_y, mb->upper_y);
        sb->upper_z = none ? mb->upper_z : render_fmaxf(sb->upper_z, mb->upper_z);
    }
    /* Offsets of secondary rays scale with the largest coordinate: float spacing grows with it. */
    const rp_bounds *b = &s->bounds;
    const float bv[6] = {b->lower_x, b->lower_y, b->lower_z, b->upper_x, b->upper_y, b->upper_z};
    float m = 1e-3f;
    for (int k = 0; k < 6; k++) {
        if (isfinite(bv[k]) && fabsf(bv[k]) > m) m = fabsf(bv[k]);
    }
    s->scale = m;
    s->extent = bounds_extent(b);
    if (data->animation) anim_scene_bounds(s); /* the same in the flat and the instanced build */
    if (!light_scene_init(s, &dd, err, err_size)) {
        char msg[600];
        snprintf(msg, sizeof msg, "%s", err && err[0] ? err : "out of memory");
        return fail(s, err, err_size, msg);
    }
    return s;
}

void rp_render_scene_release(rp_render_scene *scene) { scene_free(scene); }

bool rp_render_scene_medium(const rp_render_scene *scene, rp_bounds *bounds) {
    if (!scene || !scene->medium) return false;
    if (bounds) *bounds = scene->medium->bounds;
    return true;
}

rp_scene *rp_render_scene_core(rp_render_scene *scene) { return scene ? scene->scene : NULL; }

void rp_render_scene_intersect1(rp_render_scene *scene, rp_rayhit *rayhit) {
    if (scene && rayhit) alpha_intersect1(scene, rayhit);
}

const rp_material *rp_render_scene_material(const rp_render_scene *scene, size_t i) {
    size_t n = scene->data->material_count > 0 ? scene->data->material_count : 1;
    return i < n ? &scene->materials[i] : &scene->materials[0];
}

rp_camera rp_render_scene_default_camera(rp_render_scene *scene) {
    const rp_camera_data *c = &scene->data->camera;
    if (c->valid) {
        rp_camera cam = {.type = RP_CAMERA_PINHOLE};
        memcpy(cam.pinhole.eye, c->eye, sizeof c->eye);
        memcpy(cam.pinhole.look, c->look, sizeof c->look);
        memcpy(cam.pinhole.up, c->up, sizeof c->up);
        cam.pinhole.fov_deg = c->fov_deg;
        return cam;
    }
    return camera_frame_bounds(scene, &scene->bounds);
}

static v3 corner3(const float *a, const uint32_t *idx, uint32_t prim, int corner) {
    return v3_load(a + 3 * (size_t)idx[3 * (size_t)prim + (size_t)corner]);
}

void scene_surface(const rp_render_scene *s, const rp_ray *ray, const rp_hit *hit_in, render_surface *out) {
    const rp_scene_data *d = s->data;
    uint32_t geom = hit_in->geom_id, prim = hit_in->prim_id, inst = hit_in->inst_id;
    scene_ids_flat(s, &geom, &prim, &inst);
    v3 dir = v3_make(ray->dir_x, ray->dir_y, ray->dir_z);
    v3 org = v3_make(ray->org_x, ray->org_y, ray->org_z);
    out->p = v3_madd(org, dir, ray->tfar);
    v3 ng = v3_make(hit_in->Ng_x, hit_in->Ng_y, hit_in->Ng_z);
    v3 ns = v3_make(0, 0, 0);
    out->has_uv = false;
    out->uv[0] = out->uv[1] = 0.0f;
    out->dpdu = v3_make(0, 0, 0);
    out->color = v3_make(1, 1, 1);
    out->material = 0;
    const bool tri = geom == s->geom_ids[RENDER_GEOM_TRIANGLES] && prim < d->triangle_count;
    const bool sphere = !tri && geom == s->geom_ids[RENDER_GEOM_SPHERES] && prim < d->sphere_count;
    /* The float spacing around the point: that of the point, of the ray's origin and of the
     * primitive's coordinates. Where the point or the origin is already within 1/16 of the scene's
     * largest coordinate, the scene's (the offset before session 28, no vertex loads); only hits
     * much nearer the origin than the scene's extent (a small object on a large ground) look at
     * their primitive. */
    float mag = v3_max_abs(out->p);
    float om = v3_max_abs(org);
    if (om > mag) mag = om;
    const bool near = mag * 16.0f < s->scale;
    if (!near) mag = s->scale;
    if (tri && near) {
        for (int c = 0; c < 3; c++) {
            float vm = v3_max_abs(corner3(d->positions, d->indices, prim, c));
            if (vm > mag) mag = vm;
        }
    }
    if (om > mag) {
        /* A ray from beyond the scene's coordinates (a telephoto view from 100 times the scene's
         * size away): org + t dir is off the surface by the origin's float spacing, more than an
         * offset of mag, and shadow rays hit the surface they leave (acne over the whole image).
         * A triangle's point is rebuilt from its barycentric coordinates and a sphere's put back
         * on the sphere, so their error is the primitive's own (pbrt-v3 sec. 3.9; Waechter and
         * Binder, Ray Tracing Gems ch. 6). Animated scenes keep org + t dir and take the origin's
         * spacing: an instanced block's vertices are in its own frame, and the instanced and the
         * flat build must give the same image. */
        bool rebuilt = false;
        if (!d->animation && tri) {
            v3 c0 = corner3(d->positions, d->indices, prim, 0), c1 = corner3(d->positions, d->indices, prim, 1),
               c2 = corner3(d->positions, d->indices, prim, 2);
            float u = hit_in->u, v = hit_in->v;
            out->p = v3_add(v3_add(v3_scale(c0, 1.0f - u - v), v3_scale(c1, u)), v3_scale(c2, v));
            rebuilt = true;
        } else if (!d->animation && sphere) {
            const rp_sphere_data *sp = &d->spheres[prim];
            v3 c = v3_load(sp->center), r = v3_sub(out->p, c);
            float l = v3_length(r);
            if (l > 0.0f && isfinite(l)) out->p = v3_madd(c, r, fabsf(sp->radius) / l), rebuilt = true;
        }
        float pm = v3_max_abs(out->p);
        if (!rebuilt) mag = om;
        else if (pm > mag) mag = pm;
    }
    if (tri) {
        float u = hit_in->u, v = hit_in->v;
        float b0 = 1.0f - u - v, b1 = u, b2 = v;
        if (d->normals && d->normal_indices) {
            ns = v3_add(v3_add(v3_scale(corner3(d->normals, d->normal_indices, prim, 0), b0),
                               v3_scale(corner3(d->normals, d->normal_indices, prim, 1), b1)),
                        v3_scale(corner3(d->normals, d->normal_indices, prim, 2), b2));
        }
        if (d->colors)
            out->color = v3_add(v3_add(v3_scale(corner3(d->colors, d->indices, prim, 0), b0),
                                       v3_scale(corner3(d->colors, d->indices, prim, 1), b1)),
                                v3_scale(corner3(d->colors, d->indices, prim, 2), b2));
        uint32_t mat = d->tri_materials ? d->tri_materials[prim] : 0;
        const rp_material *m = &s->materials[mat < (d->material_count > 0 ? d->material_count : 1) ? mat : 0];
        /* texture coordinates only where the material reads a texture, and dp/du only where it has a
         * normal map (they are all that read them): the rest of the hits skip four more arrays */
        if (d->texcoords && d->texcoord_indices && (m->texture >= 0 || m->roughness_texture >= 0 || m->normal_texture >= 0 ||
                                                       m->emission_texture >= 0 || m->specular_texture >= 0)) {
            const uint32_t *ti = d->texcoord_indices + 3 * (size_t)prim;
            const float *t0 = d->texcoords + 2 * (size_t)ti[0], *t1 = d->texcoords + 2 * (size_t)ti[1],
                        *t2 = d->texcoords + 2 * (size_t)ti[2];
            float moved[3][2];
            if (m->uv_transform) {
                /* the material's texture transform (MTL -s/-o, glTF KHR_texture_transform) on the
                 * corners: the point's uv and dp/du below then follow it */
                const float *x = m->uv_matrix, *c[3] = {t0, t1, t2};
                for (int k = 0; k < 3; k++) {
                    moved[k][0] = x[0] * c[k][0] + x[1] * c[k][1] + x[2];
                    moved[k][1] = x[3] * c[k][0] + x[4] * c[k][1] + x[5];
                }
                t0 = moved[0], t1 = moved[1], t2 = moved[2];
            }
            out->uv[0] = b0 * t0[0] + b1 * t1[0] + b2 * t2[0];
            out->uv[1] = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
            out->has_uv = true;
            if (m->normal_texture >= 0) {
                /* dp/du from the triangle's edges and their uv differences (pbrt's Triangle) */
                v3 p0 = corner3(d->positions, d->indices, prim, 0), p1 = corner3(d->positions, d->indices, prim, 1),
                   p2 = corner3(d->positions, d->indices, prim, 2);
                float du02 = t0[0] - t2[0], du12 = t1[0] - t2[0], dv02 = t0[1] - t2[1], dv12 = t1[1] - t2[1];
                float det = du02 * dv12 - dv02 * du12;
                if (fabsf(det) > 1e-12f)
                    out->dpdu = v3_scale(v3_sub(v3_scale(v3_sub(p0, p2), dv12), v3_scale(v3_sub(p1, p2), dv02)), 1.0f / det);
            }
        }
        out->material = mat;
    } else if (sphere) {
        const rp_sphere_data *sp = &d->spheres[prim];
        ng = v3_sub(out->p, v3_load(sp->center));
        float cm = v3_max_abs(v3_load(sp->center)) + fabsf(sp->radius);
        if (near && cm > mag) mag = cm;
        out->material = sp->material;
        if (d->sphere_colors) out->color = v3_load(d->sphere_colors + 3 * (size_t)prim);
    } else if (geom == s->geom_ids[RENDER_GEOM_CONES] && prim < d->cone_count) {
        out->material = d->cones[prim].material;
    }
    size_t nm = d->material_count > 0 ? d->material_count : 1;
    if (out->material >= nm) out->material = 0;
    out->eps = ray_offset_at(s, mag);

    ng = v3_normalize(ng);
    if (!(v3_dot(ng, ng) > 0.5f)) ng = v3_neg(dir); /* zero-area or NaN normal */
    ns = v3_normalize(ns);
    if (!(v3_dot(ns, ns) > 0.5f)) ns = ng;
    if (v3_dot(ns, ng) < 0.0f) ns = v3_neg(ns); /* stored normals wound against the face */
    out->ns_raw = ns;
    out->entering = v3_dot(ng, dir) < 0.0f;
    if (!out->entering) {
        ng = v3_neg(ng);
        ns = v3_neg(ns);
    }
    out->ng = ng;
    out->ns = ns;
}
