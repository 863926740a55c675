/* The loaders' allocations (io_malloc and friends): malloc's, with a hook that may refuse each one,
 * so a test can fail the k-th allocation of a load (issue 23). What they return is released with
 * free(), like any malloc'ed block, so arrays move between the loaders, rp_scene_data and their
 * callers without a second allocator to match. */
#include <stdatomic.h>

#include "io/io_internal.h"

static _Atomic(io_alloc_hook_fn) hook;
static void *_Atomic hook_user;

void io_set_alloc_hook(io_alloc_hook_fn fn, void *user) {
    atomic_store(&hook_user, user);
    atomic_store(&hook, fn);
}

static _Thread_local unsigned long failures; /* this thread's allocations that returned NULL */

bool io_alloc_ok(size_t size) {
    io_alloc_hook_fn fn = atomic_load_explicit(&hook, memory_order_acquire);
    if (!fn || fn(atomic_load(&hook_user), size)) return true;
    failures++;
    return false;
}

unsigned long io_alloc_failures(void) { return failures; }

static void *counted(void *p, size_t size) {
    if (!p && size) failures++;
    return p;
}

void *io_malloc(size_t size) { return io_alloc_ok(size) ? counted(malloc(size), size) : NULL; }

void *io_calloc(size_t n, size_t size) { return io_alloc_ok(n * size) ? counted(calloc(n, size), n * size) : NULL; }

void *io_realloc(void *p, size_t size) { return io_alloc_ok(size) ? counted(realloc(p, size), size) : NULL; }

char *io_strdup(const char *s) {
    size_t n = strlen(s) + 1;
    char *d = io_malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}
