/* Timers, CPU feature detection and the thread pool. */
#define _GNU_SOURCE
#include <pthread.h>
#include <time.h>
#include <unistd.h>

#include "sys/sys.h"

double sys_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

int sys_hardware_threads(void) {
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

struct sys_pool {
    sys_allocator alloc;
    int threads; /* including the caller */
    pthread_t *workers;
    pthread_mutex_t mutex;
    pthread_cond_t wake, done;
    /* the job in flight */
    uint64_t generation;
    rp_task_fn fn;
    void *user;
    uint32_t count;
    _Atomic uint32_t next;
    int busy;       /* workers still inside the current job */
    bool quit;
    size_t bytes;   /* of this allocation */
};

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

static void *worker_main(void *p) {
    sys_pool *pool = ((worker_arg *)p)->pool;
    uint32_t thread = ((worker_arg *)p)->index;
    uint64_t seen = 0;
    pthread_mutex_lock(&pool->mutex);
    for (;;) {
        while (!pool->quit && pool->generation == seen) pthread_cond_wait(&pool->wake, &pool->mutex);
        if (pool->quit) break;
        seen = pool->generation;
        pthread_mutex_unlock(&pool->mutex);
        run_job(pool, thread);
        pthread_mutex_lock(&pool->mutex);
        if (--pool->busy == 0) pthread_cond_signal(&pool->done);
    }
    pthread_mutex_unlock(&pool->mutex);
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
    pthread_mutex_lock(&pool->mutex);
    pool->quit = true;
    pthread_cond_broadcast(&pool->wake);
    pthread_mutex_unlock(&pool->mutex);
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
    pthread_mutex_lock(&pool->mutex);
    pool->fn = fn;
    pool->user = user;
    pool->count = count;
    atomic_store_explicit(&pool->next, 0, memory_order_relaxed);
    pool->busy = pool->threads - 1;
    pool->generation++;
    pthread_cond_broadcast(&pool->wake);
    pthread_mutex_unlock(&pool->mutex);
    run_job(pool, 0);
    pthread_mutex_lock(&pool->mutex);
    while (pool->busy > 0) pthread_cond_wait(&pool->done, &pool->mutex);
    pthread_mutex_unlock(&pool->mutex);
}
