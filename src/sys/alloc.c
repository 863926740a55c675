/* Aligned allocation through the device's allocator hooks. */
#include <stdlib.h>
#include <string.h>
#if defined(__linux__)
#include <sys/mman.h>
#endif

#include "sys/sys.h"

#define SYS_HUGE_PAGE ((size_t)2 << 20)
#define SYS_HUGE_MIN ((size_t)4 << 20)

void *sys_default_alloc(void *user, void *ptr, size_t old_size, size_t new_size, size_t align) {
    RP_UNUSED(user);
    RP_UNUSED(old_size);
    if (new_size == 0) {
        free(ptr);
        return NULL;
    }
    if (align < sizeof(void *)) align = sizeof(void *);
    /* Large blocks (node arrays, triangle blocks, the builder's scratch) start on a 2 MiB boundary
     * and ask for transparent huge pages, as Embree's allocator does: a build first touches tens
     * of MiB, and with 4 KiB pages a large part of its time went to page faults. */
    bool huge = new_size >= SYS_HUGE_MIN;
    if (huge && align < SYS_HUGE_PAGE) align = SYS_HUGE_PAGE;
    void *p = NULL;
    if (posix_memalign(&p, align, new_size) != 0) return NULL;
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (huge) madvise(p, new_size & ~(size_t)(SYS_HUGE_PAGE - 1), MADV_HUGEPAGE); /* advice: failure is fine */
#endif
    if (ptr) {
        memcpy(p, ptr, old_size < new_size ? old_size : new_size);
        free(ptr);
    }
    return p;
}

void *sys_alloc(const sys_allocator *a, size_t size) {
    if (size == 0) return NULL;
    /* Round up so that SIMD loads past the end of arrays stay inside the block. */
    size = (size + RP_CACHE_LINE - 1) & ~(size_t)(RP_CACHE_LINE - 1);
    return a->fn(a->user, NULL, 0, size, RP_CACHE_LINE);
}

void *sys_calloc(const sys_allocator *a, size_t size) {
    void *p = sys_alloc(a, size);
    if (p) memset(p, 0, (size + RP_CACHE_LINE - 1) & ~(size_t)(RP_CACHE_LINE - 1));
    return p;
}

void sys_free(const sys_allocator *a, void *ptr, size_t size) {
    if (!ptr) return;
    size = (size + RP_CACHE_LINE - 1) & ~(size_t)(RP_CACHE_LINE - 1);
    a->fn(a->user, ptr, size, 0, RP_CACHE_LINE);
}
