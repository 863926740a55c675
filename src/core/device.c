/* Devices: threads, allocator hooks, kernels, and the error state of each thread. */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "core/core.h"

#define ERROR_MESSAGE_(code, msg) msg,
static const char *error_messages[] = {RP_ERROR_LIST(ERROR_MESSAGE_)};
#undef ERROR_MESSAGE_

const char *rp_error_string(rp_error code) {
    if ((unsigned)code >= RP_ERROR_COUNT) return "invalid error code";
    return error_messages[code];
}

rp_device_desc rp_device_desc_defaults(const rp_device_desc *desc) {
    rp_device_desc d = desc ? *desc : (rp_device_desc){0};
    if (d.threads <= 0) d.threads = sys_hardware_threads();
    if (!d.alloc) d.alloc = sys_default_alloc, d.alloc_user = NULL;
    if (d.isa == 0) d.isa = sys_cpu_simd_auto();
    return d;
}

const rp_kernels *device_pick_kernels(int isa) {
    switch (isa) {
    case 16: return &rp_kernels_avx512;
    case 8: return &rp_kernels_avx2;
    case 4: return &rp_kernels_sse;
    default: return &rp_kernels_scalar;
    }
}

rp_device *rp_device_new(const rp_device_desc *desc) {
    if (desc && (desc->threads < 0 || desc->threads > 1024)) return NULL;
    rp_device_desc d = rp_device_desc_defaults(desc);
    if (d.isa != 1 && d.isa != 4 && d.isa != 8 && d.isa != 16) return NULL;
    if (d.isa > sys_cpu_simd_width()) {
        if (d.error) d.error(d.error_user, RP_ERROR_UNSUPPORTED_CPU, rp_error_string(RP_ERROR_UNSUPPORTED_CPU));
        return NULL;
    }
    sys_allocator a = {d.alloc, d.alloc_user};
    rp_device *dev = sys_calloc(&a, sizeof *dev);
    if (!dev) return NULL;
    dev->desc = d;
    dev->alloc = a;
    atomic_store(&dev->refs, 1);
    dev->kernels = device_pick_kernels(d.isa);
    if (pthread_key_create(&dev->error_key, NULL) != 0) {
        sys_free(&a, dev, sizeof *dev);
        return NULL;
    }
    pthread_mutex_init(&dev->pool_lock, NULL);
    dev->pool = sys_pool_new(&a, d.threads);
    if (!dev->pool) {
        pthread_key_delete(dev->error_key);
        sys_free(&a, dev, sizeof *dev);
        return NULL;
    }
    return dev;
}

void rp_device_retain(rp_device *device) {
    if (device) atomic_fetch_add(&device->refs, 1);
}

void rp_device_release(rp_device *device) {
    if (!device || atomic_fetch_sub(&device->refs, 1) != 1) return;
    sys_pool_free(device->pool);
    pthread_mutex_destroy(&device->pool_lock);
    pthread_key_delete(device->error_key);
    sys_allocator a = device->alloc;
    sys_free(&a, device, sizeof *device);
}

void device_error(rp_device *device, rp_error code, const char *message) {
    if (!device) return;
    if ((rp_error)(intptr_t)pthread_getspecific(device->error_key) == RP_ERROR_NONE)
        pthread_setspecific(device->error_key, (void *)(intptr_t)code);
    if (device->desc.error) device->desc.error(device->desc.error_user, code, message ? message : rp_error_string(code));
}

void device_log(rp_device *device, rp_log_level level, const char *message) {
    if (device && device->desc.log) device->desc.log(device->desc.log_user, level, message);
}

rp_error rp_device_get_error(rp_device *device) {
    if (!device) return RP_ERROR_INVALID_ARGUMENT;
    rp_error e = (rp_error)(intptr_t)pthread_getspecific(device->error_key);
    pthread_setspecific(device->error_key, NULL);
    return e;
}

int rp_device_thread_count(const rp_device *device) { return device ? sys_pool_threads(device->pool) : 0; }

int rp_device_isa(const rp_device *device) { return device ? device->kernels->isa : 0; }

void rp_device_parallel_for(rp_device *device, uint32_t count, rp_task_fn fn, void *user) {
    if (!device || !fn) {
        device_error(device, RP_ERROR_INVALID_ARGUMENT, "rp_device_parallel_for: NULL device or function");
        return;
    }
    pthread_mutex_lock(&device->pool_lock);
    sys_pool_parallel_for(device->pool, count, fn, user);
    pthread_mutex_unlock(&device->pool_lock);
}
