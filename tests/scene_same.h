/* Two loads of a scene compared array by array, bit for bit (test_io_parallel, test_io_stream). */
#ifndef RP_TEST_SCENE_SAME_H
#define RP_TEST_SCENE_SAME_H

#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#include "raypack_io.h"

static bool same_bytes(const void *a, const void *b, size_t n) {
    return n == 0 || a == b || (a && b && memcmp(a, b, n) == 0);
}

/* Every array and field of two loads, bit for bit; describes the first difference into why. */
static bool same_scene(const rp_scene_data *a, const rp_scene_data *b, char *why, size_t size) {
#define SAME_N(field)                                                                              \
    if (a->field != b->field) {                                                                    \
        snprintf(why, size, #field " %zu vs %zu", (size_t)a->field, (size_t)b->field);             \
        return false;                                                                              \
    }
#define SAME_A(ptr, bytes)                                                                         \
    if ((a->ptr == NULL) != (b->ptr == NULL) || !same_bytes(a->ptr, b->ptr, bytes)) {              \
        snprintf(why, size, #ptr " differ");                                                       \
        return false;                                                                              \
    }
    SAME_N(vertex_count);
    SAME_N(normal_count);
    SAME_N(texcoord_count);
    SAME_N(triangle_count);
    SAME_N(sphere_count);
    SAME_N(cone_count);
    SAME_N(material_count);
    SAME_N(texture_count);
    SAME_N(light_count);
    SAME_N(file_bytes);
    SAME_A(positions, 3 * sizeof(float) * a->vertex_count);
    SAME_A(normals, 3 * sizeof(float) * a->normal_count);
    SAME_A(texcoords, 2 * sizeof(float) * a->texcoord_count);
    SAME_A(indices, 3 * sizeof(uint32_t) * a->triangle_count);
    SAME_A(normal_indices, 3 * sizeof(uint32_t) * a->triangle_count);
    SAME_A(texcoord_indices, 3 * sizeof(uint32_t) * a->triangle_count);
    SAME_A(tri_materials, sizeof(uint32_t) * a->triangle_count);
    SAME_A(colors, 3 * sizeof(float) * a->vertex_count);
    SAME_A(sphere_colors, 3 * sizeof(float) * a->sphere_count);
    SAME_A(spheres, sizeof(rp_sphere_data) * a->sphere_count);
    SAME_A(cones, sizeof(rp_cone_data) * a->cone_count);
    SAME_A(materials, sizeof(rp_material_data) * a->material_count);
    SAME_A(lights, sizeof(rp_light_data) * a->light_count);
    for (size_t i = 0; i < a->texture_count; i++) {
        const rp_texture_data *x = &a->textures[i], *y = &b->textures[i];
        if (strcmp(x->path, y->path) != 0 || x->width != y->width || x->height != y->height ||
            !same_bytes(x->rgb, y->rgb, 3 * (size_t)x->width * (size_t)x->height) || !x->alpha != !y->alpha ||
            (x->alpha && !same_bytes(x->alpha, y->alpha, (size_t)x->width * (size_t)x->height))) {
            snprintf(why, size, "texture %zu differs", i);
            return false;
        }
    }
    if (memcmp(&a->camera, &b->camera, sizeof a->camera) != 0 || memcmp(a->background, b->background, sizeof a->background) != 0 ||
        a->has_background != b->has_background) {
        snprintf(why, size, "camera or background differ");
        return false;
    }
#undef SAME_N
#undef SAME_A
    return true;
}

/* The animations of two loads (what the NFF/AFF parser writes of them), bit for bit. */
static inline bool same_animation(const rp_scene_data *x, const rp_scene_data *y, char *why, size_t size) {
    const rp_animation_data *a = x->animation, *b = y->animation;
    if (!a || !b) {
        if (a != b) snprintf(why, size, "animation in one load only");
        return a == b;
    }
    bool same = a->start == b->start && a->end == b->end && a->frames == b->frames && a->node_count == b->node_count &&
                a->key_count == b->key_count && a->vis_count == b->vis_count && a->tpa_count == b->tpa_count &&
                same_bytes(a->nodes, b->nodes, a->node_count * sizeof *a->nodes) &&
                same_bytes(a->keys, b->keys, a->key_count * sizeof *a->keys) &&
                same_bytes(a->vis_times, b->vis_times, a->vis_count * sizeof(float)) &&
                same_bytes(a->vis_values, b->vis_values, a->vis_count) &&
                same_bytes(a->tpas, b->tpas, a->tpa_count * sizeof *a->tpas) &&
                same_bytes(a->tri_node, b->tri_node, x->triangle_count * sizeof(int32_t)) &&
                memcmp(a->camera, b->camera, sizeof a->camera) == 0;
    if (!same) snprintf(why, size, "animations differ");
    return same;
}

#endif
