/* Geometries: buffers (shared or owned) and user callbacks. */
#include <math.h>
#include <string.h>

#include "core/core.h"

static size_t format_size(rp_format f) {
    switch (f) {
    case RP_FORMAT_FLOAT3: return 12;
    case RP_FORMAT_FLOAT4: return 16;
    case RP_FORMAT_UINT3: return 12;
    }
    return 0;
}

rp_geometry *rp_geometry_new(rp_device *device, rp_geometry_type type) {
    if (!device) return NULL;
    if (type != RP_GEOMETRY_TRIANGLE && type != RP_GEOMETRY_SPHERE && type != RP_GEOMETRY_USER &&
        type != RP_GEOMETRY_INSTANCE) {
        device_error(device, RP_ERROR_INVALID_ARGUMENT, "rp_geometry_new: unknown geometry type");
        return NULL;
    }
    rp_geometry *g = sys_calloc(&device->alloc, sizeof *g);
    if (!g) {
        device_error(device, RP_ERROR_OUT_OF_MEMORY, NULL);
        return NULL;
    }
    atomic_store(&g->refs, 1);
    g->device = device;
    g->type = type;
    g->mask = 0xFFFFFFFFu;
    rp_device_retain(device);
    return g;
}

void rp_geometry_retain(rp_geometry *geometry) {
    if (geometry) atomic_fetch_add(&geometry->refs, 1);
}

static void free_owned(rp_geometry *g, geom_buffer *b) {
    if (b->owned) sys_free(&g->device->alloc, b->owned, b->owned_bytes);
    memset(b, 0, sizeof *b);
}

void rp_geometry_release(rp_geometry *geometry) {
    if (!geometry || atomic_fetch_sub(&geometry->refs, 1) != 1) return;
    rp_device *dev = geometry->device;
    free_owned(geometry, &geometry->buffers[0]);
    free_owned(geometry, &geometry->buffers[1]);
    rp_scene_release(geometry->inst);
    sys_free(&dev->alloc, geometry, sizeof *geometry);
    rp_device_release(dev);
}

/* Checks that a buffer slot, format and stride make sense for this geometry. */
static bool check_buffer(rp_geometry *g, rp_buffer_type type, rp_format format, size_t stride, const char *fn) {
    bool ok;
    switch (g->type) {
    case RP_GEOMETRY_TRIANGLE:
        ok = (type == RP_BUFFER_VERTEX && (format == RP_FORMAT_FLOAT3 || format == RP_FORMAT_FLOAT4)) ||
             (type == RP_BUFFER_INDEX && format == RP_FORMAT_UINT3);
        break;
    case RP_GEOMETRY_SPHERE: ok = type == RP_BUFFER_VERTEX && format == RP_FORMAT_FLOAT4; break;
    case RP_GEOMETRY_USER:
    case RP_GEOMETRY_INSTANCE: ok = false; break;
    default: ok = false; break;
    }
    if (!ok) {
        device_error(g->device, RP_ERROR_INVALID_ARGUMENT, fn);
        return false;
    }
    if ((stride != 0 && stride < format_size(format)) || stride % 4 != 0) {
        device_error(g->device, RP_ERROR_INVALID_ARGUMENT, fn);
        return false;
    }
    return true;
}

void rp_geometry_set_buffer(rp_geometry *geometry, rp_buffer_type type, rp_format format, const void *data,
                            size_t byte_offset, size_t byte_stride, size_t count) {
    if (!geometry) return;
    if ((unsigned)type > RP_BUFFER_INDEX || (!data && count > 0) || byte_offset % 4 != 0) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT, "rp_geometry_set_buffer: bad buffer");
        return;
    }
    if (!check_buffer(geometry, type, format, byte_stride, "rp_geometry_set_buffer: bad type, format or stride"))
        return;
    geom_buffer *b = &geometry->buffers[type];
    /* new vertices in the same number are moved vertices; anything else changes the topology */
    if (type != RP_BUFFER_VERTEX || !b->set || b->count != count || b->format != format) geometry->topo++;
    free_owned(geometry, b);
    b->data = (const uint8_t *)data + byte_offset;
    b->stride = byte_stride ? byte_stride : format_size(format);
    b->count = count;
    b->format = format;
    b->set = true;
}

void *rp_geometry_new_buffer(rp_geometry *geometry, rp_buffer_type type, rp_format format, size_t byte_stride,
                             size_t count) {
    if (!geometry) return NULL;
    if ((unsigned)type > RP_BUFFER_INDEX) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT, "rp_geometry_new_buffer: bad buffer type");
        return NULL;
    }
    if (!check_buffer(geometry, type, format, byte_stride, "rp_geometry_new_buffer: bad type, format or stride"))
        return NULL;
    size_t stride = byte_stride ? byte_stride : format_size(format);
    if (count > ((size_t)1 << 40) / stride) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT, "rp_geometry_new_buffer: absurd count");
        return NULL;
    }
    size_t bytes = stride * count + 16; /* padding: SIMD loads may read a little past the end */
    void *p = sys_calloc(&geometry->device->alloc, bytes);
    if (!p) {
        device_error(geometry->device, RP_ERROR_OUT_OF_MEMORY, NULL);
        return NULL;
    }
    geom_buffer *b = &geometry->buffers[type];
    geometry->topo++;
    free_owned(geometry, b);
    b->owned = p;
    b->owned_bytes = bytes;
    b->data = p;
    b->stride = stride;
    b->count = count;
    b->format = format;
    b->set = true;
    return p;
}

void rp_geometry_set_user(rp_geometry *geometry, uint32_t prim_count, rp_user_bounds_fn bounds,
                          rp_user_intersect_fn intersect, rp_user_occluded_fn occluded, void *user) {
    if (!geometry) return;
    if (geometry->type != RP_GEOMETRY_USER || !bounds || !intersect || !occluded) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT,
                     "rp_geometry_set_user: not a user geometry, or a NULL callback");
        return;
    }
    geometry->topo++;
    geometry->user_count = prim_count;
    geometry->user_bounds = bounds;
    geometry->user_intersect = intersect;
    geometry->user_occluded = occluded;
    geometry->user = user;
}

void rp_geometry_set_mask(rp_geometry *geometry, uint32_t mask) {
    if (geometry) geometry->mask = mask, geometry->topo++;
}

void rp_geometry_update(rp_geometry *geometry, rp_buffer_type type) {
    if (!geometry) return;
    if ((unsigned)type > RP_BUFFER_INDEX) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT, "rp_geometry_update: bad buffer type");
        return;
    }
    /* vertices: nothing to record, a commit reads them again; indices: a new topology */
    if (type == RP_BUFFER_INDEX || geometry->type != RP_GEOMETRY_TRIANGLE) geometry->topo++;
}

void rp_geometry_commit(rp_geometry *geometry) {
    if (!geometry) return;
    bool ok = true;
    switch (geometry->type) {
    case RP_GEOMETRY_TRIANGLE: ok = geometry->buffers[RP_BUFFER_VERTEX].set && geometry->buffers[RP_BUFFER_INDEX].set; break;
    case RP_GEOMETRY_SPHERE: ok = geometry->buffers[RP_BUFFER_VERTEX].set; break;
    case RP_GEOMETRY_USER: ok = geometry->user_intersect != NULL; break;
    case RP_GEOMETRY_INSTANCE: ok = geometry->inst != NULL; break;
    }
    if (!ok) device_error(geometry->device, RP_ERROR_INVALID_GEOMETRY, "rp_geometry_commit: a buffer or callback is missing");
}

/* Inverse of a row-major 3x4 affine map (false when singular). */
static bool affine_inverse(const float m[12], float out[12]) {
    double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    double A = e * i - f * h, B = f * g - d * i, C = d * h - e * g;
    double det = a * A + b * B + c * C;
    if (!(fabs(det) > 1e-30) || !isfinite(det)) return false;
    double r[9] = {A / det, (c * h - b * i) / det, (b * f - c * e) / det,
                   B / det, (a * i - c * g) / det, (c * d - a * f) / det,
                   C / det, (b * g - a * h) / det, (a * e - b * d) / det};
    for (int row = 0; row < 3; row++) {
        double t = -(r[3 * row] * m[3] + r[3 * row + 1] * m[7] + r[3 * row + 2] * m[11]);
        for (int k = 0; k < 3; k++) out[4 * row + k] = (float)r[3 * row + k];
        out[4 * row + 3] = (float)t;
    }
    for (int k = 0; k < 12; k++)
        if (!isfinite(out[k])) return false;
    return true;
}

void rp_geometry_set_instance(rp_geometry *geometry, rp_scene *scene, const float xfm[12]) {
    if (!geometry) return;
    float inv[12];
    if (geometry->type != RP_GEOMETRY_INSTANCE || !scene || !xfm || scene->device != geometry->device ||
        !affine_inverse(xfm, inv)) {
        device_error(geometry->device, RP_ERROR_INVALID_ARGUMENT,
                     "rp_geometry_set_instance: not an instance, no scene (or another device's), or a singular transform");
        return;
    }
    rp_scene_retain(scene);
    rp_scene_release(geometry->inst);
    geometry->inst = scene;
    memcpy(geometry->xfm, xfm, sizeof geometry->xfm);
    memcpy(geometry->inv, inv, sizeof geometry->inv);
    geometry->topo++;
}
