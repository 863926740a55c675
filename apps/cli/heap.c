/* The command's heap on 2 MiB pages (what glibc does with GLIBC_TUNABLES=glibc.malloc.hugetlb=1).
 *
 * On the virtual machines raypack is measured on, the first touch of a 4 KiB page costs 10-14 us
 * (a fault, the page cleared and charged); a 2 MiB page costs about 0.14 ms for 512 times the
 * memory. The loaders put their blocks from 1 MiB on huge pages themselves (io_malloc), but the
 * rest of a load and a build is many smaller blocks from malloc's heap: growing arrays that
 * realloc copies into fresh pages, decoded textures, the builders' scratch. bart_kitchen took some
 * 6,000 faults in its load and build, about 60 ms of its 150.
 *
 * So the command, before it allocates anything itself, lets malloc's heap grow in one large step
 * (M_TOP_PAD: address space only; pages come when touched) and advises that range MADV_HUGEPAGE,
 * and has blocks below 32 MiB come from the heap rather than from their own 4 KiB mappings
 * (M_MMAP_THRESHOLD, which also stops glibc's threshold from moving). The heap is not trimmed
 * below the reservation (M_TRIM_THRESHOLD). A heap that outgrows the reservation goes on growing
 * on 4 KiB pages, as before; a heap that cannot grow (a limit on address space) leaves malloc to
 * map its blocks, as before. RAYPACK_HUGE_HEAP=0 turns it off. This is a process-wide choice, so
 * it is the command's, not the library's: programs embedding raypack can set the glibc tunable. */
#include "cli.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define CLI_HEAP_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define CLI_HEAP_SANITIZED 1
#endif

#if defined(__linux__) && defined(__GLIBC__) && !defined(CLI_HEAP_SANITIZED)
#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>
#define CLI_HEAP_HUGE 1
#endif

bool cli_heap_hugepages(size_t reserve) {
#if defined(CLI_HEAP_HUGE) && defined(MADV_HUGEPAGE)
    const char *env = getenv("RAYPACK_HUGE_HEAP");
    if (env && strcmp(env, "0") == 0) return false;
    const uintptr_t huge = (uintptr_t)2 << 20;
    if (reserve < huge || reserve > (size_t)1 << 30) return false;
    if (!mallopt(M_MMAP_THRESHOLD, 32 << 20) || !mallopt(M_TRIM_THRESHOLD, (int)reserve) ||
        !mallopt(M_TOP_PAD, (int)reserve))
        return false;
    void *p = malloc((size_t)1 << 20); /* the heap grows by the pad now, not bit by bit later */
    if (!p) return false;
    uintptr_t a = ((uintptr_t)p + huge - 1) & ~(huge - 1), b = (uintptr_t)sbrk(0);
    bool ok = (uintptr_t)p < b && b > a && madvise((void *)a, b - a, MADV_HUGEPAGE) == 0;
    free(p);
    return ok;
#else
    (void)reserve;
    return false;
#endif
}
