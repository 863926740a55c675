/* Threads for the loaders: a parallel for over the chunks of a large text file. raypack_io does
 * not link the core library, so it cannot borrow a device's pool; a load starts its threads and
 * joins them before it returns (a few tens of microseconds against loads of milliseconds). */
#include <pthread.h>
#include <stdatomic.h>
#include <string.h>
#include <unistd.h>

#include "io/io_internal.h"

#define IO_MAX_THREADS 64

typedef struct io_par_job {
    io_task_fn fn;
    void *user;
    uint32_t count;
    atomic_uint next;
} io_par_job;

static void *par_worker(void *arg) {
    io_par_job *job = arg;
    for (;;) {
        uint32_t i = atomic_fetch_add(&job->next, 1u);
        if (i >= job->count) break;
        job->fn(job->user, i);
    }
    return NULL;
}

int io_threads_resolve(int threads) {
    if (threads <= 0) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        threads = n > 0 ? (int)n : 1;
    }
    return threads > IO_MAX_THREADS ? IO_MAX_THREADS : threads;
}

void io_parallel_for(int threads, uint32_t count, io_task_fn fn, void *user) {
    io_par_job job = {.fn = fn, .user = user, .count = count};
    atomic_init(&job.next, 0u);
    pthread_t tid[IO_MAX_THREADS];
    int started = 0;
    int want = threads < (int)count ? threads : (int)count;
    if (want > IO_MAX_THREADS) want = IO_MAX_THREADS;
    for (int t = 1; t < want; t++) {
        if (pthread_create(&tid[started], NULL, par_worker, &job) != 0) break; /* the rest on this thread */
        started++;
    }
    par_worker(&job);
    for (int t = 0; t < started; t++) pthread_join(tid[t], NULL);
}

size_t io_text_vertex_hint(const char *p, const char *end) {
    size_t lines = 0, most = (size_t)(end - p) / 6 + 16;
    for (; p < end && lines < most; lines++) {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        if (!nl) break;
        p = nl + 1;
    }
    return lines < most ? lines + 16 : most;
}

uint32_t io_split_lines(const char *data, size_t size, uint32_t k, const char **starts) {
    const char *end = data + size;
    uint32_t n = 0;
    for (uint32_t i = 0; i < k; i++) {
        const char *s = data + (uint64_t)size * i / k;
        if (s > data && s[-1] != '\n') {
            const char *nl = memchr(s, '\n', (size_t)(end - s));
            s = nl ? nl + 1 : end;
        }
        if (s >= end || (n && s <= starts[n - 1])) continue;
        starts[n++] = s;
    }
    return n;
}
