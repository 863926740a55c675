/* apps/cli/heap.c: the command's heap on 2 MiB pages. After cli_heap_hugepages, a block from the
 * heap lies in a mapping advised MADV_HUGEPAGE ("hg" in /proc/self/smaps), and once written it is
 * backed by huge pages where the kernel offers them (transparent_hugepage "madvise" or "always");
 * RAYPACK_HUGE_HEAP=0 turns it off; absurd reservations are refused. Sanitizer builds (their own
 * allocators) leave the heap alone. */
#include "rp_test.h"

#include "../apps/cli/heap.c"

#include <stdint.h>
#include <stdio.h>

#if defined(CLI_HEAP_HUGE) && defined(MADV_HUGEPAGE)
/* The smaps entry of the mapping that holds p: its VmFlags line and AnonHugePages (kB). */
static bool mapping_of(const void *p, char *flags, size_t size, long *huge_kb) {
    FILE *f = fopen("/proc/self/smaps", "r");
    if (!f) return false;
    char line[512];
    bool in = false, found = false;
    flags[0] = '\0';
    *huge_kb = -1;
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' ')) {
            if (found) break;
            in = (uintptr_t)p >= lo && (uintptr_t)p < hi;
            found = in;
            continue;
        }
        if (!in) continue;
        if (strncmp(line, "AnonHugePages:", 14) == 0) *huge_kb = strtol(line + 14, NULL, 10);
        if (strncmp(line, "VmFlags:", 8) == 0) snprintf(flags, size, "%s", line + 8);
    }
    fclose(f);
    return found;
}

static bool thp_offered(void) {
    FILE *f = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    if (!f) return false;
    char s[128] = "";
    bool ok = fgets(s, sizeof s, f) && (strstr(s, "[madvise]") || strstr(s, "[always]"));
    fclose(f);
    return ok;
}
#endif

int main(void) {
    setenv("RAYPACK_HUGE_HEAP", "0", 1);
    CHECK(!cli_heap_hugepages((size_t)64 << 20)); /* turned off */
    unsetenv("RAYPACK_HUGE_HEAP");
    CHECK(!cli_heap_hugepages(4096));             /* less than a huge page */
    CHECK(!cli_heap_hugepages((size_t)4 << 30));  /* more than the cap */
    bool ok = cli_heap_hugepages((size_t)64 << 20);
#if defined(CLI_HEAP_HUGE) && defined(MADV_HUGEPAGE)
    CHECK(ok);
    /* 8 MiB: below the 32 MiB mmap threshold, so from the heap, inside the reservation */
    size_t n = (size_t)8 << 20;
    char *p = malloc(n);
    CHECK(p != NULL);
    if (p) {
        memset(p, 1, n);
        char flags[512];
        long huge_kb = -1;
        CHECK(mapping_of(p + n / 2, flags, sizeof flags, &huge_kb));
        CHECKF(strstr(flags, " hg") != NULL, "VmFlags:%s", flags);
        if (thp_offered()) CHECKF(huge_kb >= 2048, "AnonHugePages %ld kB", huge_kb);
        else printf("transparent huge pages not offered by this kernel: backing not checked\n");
        /* the blocks stay usable: grown, shrunk, freed */
        char *q = realloc(p, 2 * n);
        CHECK(q != NULL && q[0] == 1 && q[n - 1] == 1);
        if (q) p = q;
        free(p);
    }
    void *big = malloc((size_t)40 << 20); /* above the threshold: a mapping of its own, as before */
    CHECK(big != NULL);
    free(big);
#else
    CHECK(!ok); /* sanitizers' allocators: the heap is theirs */
    printf("sanitizer build or no glibc: the heap is left alone\n");
#endif
    return RP_TEST_END();
}
