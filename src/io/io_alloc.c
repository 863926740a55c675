/* The loaders' allocations (io_malloc and friends): malloc's, with a hook that may refuse each one,
 * so a test can fail the k-th allocation of a load (issue 23). What they return is released with
 * free(), like any malloc'ed block, so arrays move between the loaders, rp_scene_data and their
 * callers without a second allocator to match. */
#include <stdatomic.h>
#include <stdint.h>
#if defined(__linux__)
#include <sys/mman.h>
#endif

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

/* Blocks this large (the inflated text, the builder's arrays, a chunk's) ask for transparent huge
 * pages, as the core's allocator does (sys_default_alloc): a load first touches hundreds of MB,
 * and with 4 KiB pages faulting them in cost more than inflating and parsing them (the SPD tree's
 * 182 MB: about 600 ms of faults on 4 KiB pages on a virtual machine, 20 ms on 2 MiB pages). The
 * advice covers the 2 MiB pages that lie wholly inside the block, so the block stays malloc's. */
#define IO_HUGE_PAGE ((uintptr_t)2 << 20)
#define IO_HUGE_MIN ((size_t)4 << 20)

static void *counted(void *p, size_t size) {
    if (!p && size) failures++;
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (p && size >= IO_HUGE_MIN) {
        uintptr_t lo = ((uintptr_t)p + IO_HUGE_PAGE - 1) & ~(IO_HUGE_PAGE - 1);
        uintptr_t hi = ((uintptr_t)p + size) & ~(IO_HUGE_PAGE - 1);
        if (hi > lo) madvise((void *)lo, hi - lo, MADV_HUGEPAGE); /* advice: failure is fine */
    }
#endif
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
