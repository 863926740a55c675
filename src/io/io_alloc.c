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

/* Blocks from 1 MiB (the inflated text of a small scene, a chunk's arrays) are placed on 2 MiB
 * boundaries and rounded up to whole 2 MiB pages, so that all of a block can be a huge page: a
 * 3 MB block from malloc lies across two 2 MiB pages without holding either, and its 740 faults on
 * 4 KiB pages cost the bunny's load some 20 ms here, three times its parse (docs/loading.md). Only
 * address space is rounded up: the pages past the end are never touched. */
#define IO_ALIGN_MIN ((size_t)1 << 20)

static void *huge_alloc(size_t size) {
    size_t round = (size + IO_HUGE_PAGE - 1) & ~(size_t)(IO_HUGE_PAGE - 1);
    if (round < size) return NULL;
    void *p = aligned_alloc(IO_HUGE_PAGE, round);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (p) madvise(p, round, MADV_HUGEPAGE); /* advice: failure is fine */
#endif
    if (!p) failures++;
    return p;
}

void *io_malloc(size_t size) {
    if (!io_alloc_ok(size)) return NULL;
    return size >= IO_ALIGN_MIN ? huge_alloc(size) : counted(malloc(size), size);
}

void *io_calloc(size_t n, size_t size) { return io_alloc_ok(n * size) ? counted(calloc(n, size), n * size) : NULL; }

/* A first reservation (p NULL) is an io_malloc; a block that grows stays realloc's (glibc moves a
 * large one with mremap, without copying), advised as before. */
void *io_realloc(void *p, size_t size) {
    if (!io_alloc_ok(size)) return NULL;
    return !p && size >= IO_ALIGN_MIN ? huge_alloc(size) : counted(realloc(p, size), size);
}

char *io_strdup(const char *s) {
    size_t n = strlen(s) + 1;
    char *d = io_malloc(n);
    if (d) memcpy(d, s, n);
    return d;
}
