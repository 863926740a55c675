/* Timers, CPU feature detection and the thread pool. */
#define _GNU_SOURCE
#include <pthread.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>
#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#include <x86intrin.h>
#endif

#include "sys/sys.h"

double sys_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

uint64_t sys_ticks(void) {
#if defined(__x86_64__) || defined(__i386__)
    return __rdtsc();
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
#endif
}

/* The CPUs this process may run on (a container's or taskset's cpuset, not the host's count), so
 * the default pool and the pool's spinning (sys_pool_new) match the cores there are. */
int sys_hardware_threads(void) {
#if defined(__linux__)
    cpu_set_t set;
    if (sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
#endif
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : (int)n;
}

int sys_cpu_simd_width(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
        __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq"))
        return 16;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return 8;
    if (__builtin_cpu_supports("sse4.2")) return 4;
#endif
    return 1;
}

/* The width a device gets when its desc leaves isa 0. The widest the CPU has, except on Intel CPUs
 * whose cores lower their clock while they run 512-bit instructions (Skylake-SP to Ice Lake: the
 * ones with AVX-512 and without AVX-VNNI, glibc's rule for Prefer_No_AVX512): there AVX2. The lower
 * clock stays on the whole core, so the scalar shading between traversals slows with it: on an Ice
 * Lake Xeon (model 106) scene_surface took 24% more samples in a frame with the AVX-512 kernels, and
 * every integrator's frames ran 1-18% faster with AVX2 (docs/animation.md). --isa avx512 still
 * picks them. */
int sys_cpu_simd_auto(void) {
    int width = sys_cpu_simd_width();
#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
    if (width == 16 && __builtin_cpu_is("intel")) {
        unsigned a, b, c, d;
        bool avx_vnni = false;
        if (__get_cpuid_max(0, NULL) >= 7) {
            __cpuid_count(7, 1, a, b, c, d);
            avx_vnni = (a >> 4) & 1u; /* CPUID.(EAX=7,ECX=1):EAX[4] */
        }
        if (!avx_vnni) width = 8;
    }
#endif
    return width;
}

struct sys_pool {
    sys_allocator alloc;
    int threads; /* including the caller */
    pthread_t *workers;
    pthread_mutex_t mutex;
    pthread_cond_t wake, done;
    /* the job in flight: published by bumping generation (after fn, user, count, next, busy) */
    _Atomic uint64_t generation;
    rp_task_fn fn;
    void *user;
    uint32_t count;
    _Atomic uint32_t next;
    _Atomic int busy;     /* workers still inside the current job */
    _Atomic int sleepers; /* workers waiting on `wake` (or about to) */
    _Atomic bool quit;
    int spin;             /* pauses a waiting thread spins before it sleeps (0 when oversubscribed) */
    size_t bytes;         /* of this allocation */
};

/* Waiting spins this many pauses (some tens of microseconds) before it sleeps: a build runs dozens
 * of short parallel loops back to back, and a sleeping thread took longer to wake than many of
 * them ran (bart_museum5: 1.4 ms builds on two threads against 1.95 on one). Not when the pool has
 * more threads than the machine: spinning threads then take the cores from working ones (spd_tree
 * built in 783 ms on 64 threads on 2 cores, 343 ms sleeping at once). */
#ifndef SYS_SPIN
#define SYS_SPIN 4096
#endif

static inline void cpu_pause(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ volatile("yield");
#endif
}

typedef struct worker_arg {
    sys_pool *pool;
    uint32_t index;
} worker_arg;

static void run_job(sys_pool *pool, uint32_t thread) {
    for (;;) {
        uint32_t i = atomic_fetch_add_explicit(&pool->next, 1, memory_order_relaxed);
        if (i >= pool->count) break;
        pool->fn(pool->user, i, thread);
    }
}

/* The generation after `seen`, spinning a while before sleeping on `wake`. The sleeper count and
 * the generation are sequentially consistent: a publisher that bumps the generation and then sees
 * no sleeper knows every worker about to sleep will see the new generation first. */
static uint64_t wait_generation(sys_pool *pool, uint64_t seen) {
    for (int i = 0; i < pool->spin; i++) {
        uint64_t g = atomic_load_explicit(&pool->generation, memory_order_acquire);
        if (g != seen) return g;
        cpu_pause();
    }
    pthread_mutex_lock(&pool->mutex);
    atomic_fetch_add(&pool->sleepers, 1);
    uint64_t g;
    while ((g = atomic_load(&pool->generation)) == seen) pthread_cond_wait(&pool->wake, &pool->mutex);
    atomic_fetch_sub(&pool->sleepers, 1);
    pthread_mutex_unlock(&pool->mutex);
    return g;
}

/* Bumps the generation and wakes the sleepers, if any. */
static void publish(sys_pool *pool) {
    atomic_fetch_add(&pool->generation, 1);
    if (atomic_load(&pool->sleepers) > 0) {
        pthread_mutex_lock(&pool->mutex);
        pthread_cond_broadcast(&pool->wake);
        pthread_mutex_unlock(&pool->mutex);
    }
}

static void *worker_main(void *p) {
    sys_pool *pool = ((worker_arg *)p)->pool;
    uint32_t thread = ((worker_arg *)p)->index;
    uint64_t seen = 0;
    for (;;) {
        seen = wait_generation(pool, seen);
        if (atomic_load(&pool->quit)) break;
        run_job(pool, thread);
        if (atomic_fetch_sub(&pool->busy, 1) == 1) {
            pthread_mutex_lock(&pool->mutex);
            pthread_cond_signal(&pool->done);
            pthread_mutex_unlock(&pool->mutex);
        }
    }
    return NULL;
}

sys_pool *sys_pool_new(const sys_allocator *a, int threads) {
    if (threads < 1) threads = 1;
    size_t size = sizeof(sys_pool) + (size_t)threads * (sizeof(pthread_t) + sizeof(worker_arg));
    sys_pool *pool = sys_calloc(a, size);
    if (!pool) return NULL;
    pool->alloc = *a;
    pool->bytes = size;
    pool->threads = threads;
    pool->spin = threads <= sys_hardware_threads() ? SYS_SPIN : 0;
    pool->workers = (pthread_t *)(pool + 1);
    worker_arg *args = (worker_arg *)(pool->workers + threads);
    pthread_mutex_init(&pool->mutex, NULL);
    pthread_cond_init(&pool->wake, NULL);
    pthread_cond_init(&pool->done, NULL);
    for (int i = 1; i < threads; i++) {
        args[i].pool = pool;
        args[i].index = (uint32_t)i;
        if (pthread_create(&pool->workers[i], NULL, worker_main, &args[i]) != 0) {
            pool->threads = i; /* run with the threads we got */
            break;
        }
    }
    return pool;
}

void sys_pool_free(sys_pool *pool) {
    if (!pool) return;
    atomic_store(&pool->quit, true);
    publish(pool);
    for (int i = 1; i < pool->threads; i++) pthread_join(pool->workers[i], NULL);
    pthread_mutex_destroy(&pool->mutex);
    pthread_cond_destroy(&pool->wake);
    pthread_cond_destroy(&pool->done);
    sys_allocator a = pool->alloc;
    sys_free(&a, pool, pool->bytes);
}

int sys_pool_threads(const sys_pool *pool) { return pool->threads; }

void sys_pool_parallel_for(sys_pool *pool, uint32_t count, rp_task_fn fn, void *user) {
    if (count == 0) return;
    if (pool->threads == 1 || count == 1) {
        for (uint32_t i = 0; i < count; i++) fn(user, i, 0);
        return;
    }
    pool->fn = fn;
    pool->user = user;
    pool->count = count;
    atomic_store_explicit(&pool->next, 0, memory_order_relaxed);
    atomic_store_explicit(&pool->busy, pool->threads - 1, memory_order_relaxed);
    publish(pool);
    run_job(pool, 0);
    for (int i = 0; i < pool->spin && atomic_load_explicit(&pool->busy, memory_order_acquire) > 0; i++) cpu_pause();
    if (atomic_load_explicit(&pool->busy, memory_order_acquire) > 0) {
        pthread_mutex_lock(&pool->mutex);
        while (atomic_load(&pool->busy) > 0) pthread_cond_wait(&pool->done, &pool->mutex);
        pthread_mutex_unlock(&pool->mutex);
    }
}
