/* System layer: allocation through the device's hooks, the thread pool, timers, CPU features. */
#ifndef RP_SYS_H
#define RP_SYS_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack.h"

#define RP_CACHE_LINE 64
#define RP_UNUSED(x) ((void)(x))
#define RP_LIKELY(x) __builtin_expect(!!(x), 1)
#define RP_UNLIKELY(x) __builtin_expect(!!(x), 0)
#define RP_INLINE static inline __attribute__((always_inline))
#define RP_HIDDEN __attribute__((visibility("hidden")))

/* Allocator: the device's hooks (Lua's lua_Alloc shape, with alignment). */
typedef struct sys_allocator {
    rp_alloc_fn fn;
    void *user;
} sys_allocator;

void *sys_default_alloc(void *user, void *ptr, size_t old_size, size_t new_size, size_t align);
/* Allocates size bytes aligned to 64; NULL on failure or size 0. */
void *sys_alloc(const sys_allocator *a, size_t size);
/* Allocates zeroed memory aligned to 64. */
void *sys_calloc(const sys_allocator *a, size_t size);
/* Frees memory from sys_alloc (size must be the allocated size). */
void sys_free(const sys_allocator *a, void *ptr, size_t size);

/* Monotonic time in seconds. */
double sys_seconds(void);
/* A tick count for timing spans of microseconds at the cost of a few cycles: the time-stamp
 * counter on x86 (constant rate on the CPUs raypack targets), nanoseconds elsewhere. */
uint64_t sys_ticks(void);
/* Number of hardware threads. */
int sys_hardware_threads(void);
/* Widest SIMD the CPU and OS support: 16 (AVX-512 F/VL/BW/DQ), 8 (AVX2+FMA), 4 (SSE4.2) or 1. */
int sys_cpu_simd_width(void);
/* The width isa 0 (auto) picks: sys_cpu_simd_width(), but 8 on Intel CPUs that lower their clock
 * under AVX-512 (sys.c). */
int sys_cpu_simd_auto(void);

/* Thread pool: workers wait on a condition variable; parallel_for hands out indices with an
 * atomic counter, the calling thread working too. */
typedef struct sys_pool sys_pool;
sys_pool *sys_pool_new(const sys_allocator *a, int threads);
void sys_pool_free(sys_pool *pool);
int sys_pool_threads(const sys_pool *pool);
void sys_pool_parallel_for(sys_pool *pool, uint32_t count, rp_task_fn fn, void *user);

#endif
