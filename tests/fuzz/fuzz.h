/* Shared by the fuzz harnesses (issue 23): each harness is one LLVMFuzzerTestOneInput over one
 * parser, built twice: with clang's libFuzzer (+ASan/UBSan; `make fuzz`) and with replay.c's main()
 * for the gcc builds, where CTest replays the seed corpus and every past crash reproducer.
 *
 * An input may hold several files, split at lines "%%" (FUZZ_SPLIT): the first is the scene the
 * harness names, the rest the files it may include or reference (b.*, c.*, t.ppm ...), served from
 * memory through io_load_memory, so includes, material libraries and textures are fuzzed without
 * touching the disk. */
#ifndef RP_FUZZ_H
#define RP_FUZZ_H

#include <stddef.h>
#include <stdio.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "io/io_internal.h"

#define FUZZ_SPLIT "\n%%\n"
#define FUZZ_MAX_FILES 6

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Lower caps than the defaults (which admit real scenes), so a hostile size fails fast instead of
 * spending the run on a few huge allocations; the caps themselves are what is under test. */
__attribute__((constructor)) static void fuzz_limits(void) {
    setenv("RP_MAX_TEXTURE_PIXELS", "64k", 0);
    setenv("RP_MAX_FILE_BYTES", "64M", 0);
    setenv("RP_MAX_INCLUDE_BYTES", "64M", 0);
    setenv("RP_MAX_INCLUDES", "256", 0);
}

/* Loads data as files named names[0..count) (split at FUZZ_SPLIT; the last piece takes the rest),
 * then frees everything: crashes, leaks, hangs and UB are the only failures, a rejected file is a
 * normal outcome. With archive, the whole input is one tar(.gz) image. */
static inline void fuzz_load(const uint8_t *data, size_t size, const char *const *names, int count, bool archive) {
    io_entry files[FUZZ_MAX_FILES];
    int n = 0;
    const char *p = (const char *)data, *end = p + size;
    while (n < count && n < FUZZ_MAX_FILES) {
        const char *cut = NULL;
        if (n + 1 < count)
            for (const char *q = p; q + 4 <= end; q++)
                if (memcmp(q, FUZZ_SPLIT, 4) == 0) {
                    cut = q;
                    break;
                }
        const char *stop = cut ? cut + 1 : end; /* a piece keeps its last newline */
        size_t len = (size_t)(stop - p);
        char *copy = malloc(len + 1); /* io_buf's contract: a NUL one past the end */
        if (!copy) break;
        if (len) memcpy(copy, p, len);
        copy[len] = '\0';
        files[n].name = (char *)names[n];
        files[n].data = copy;
        files[n].size = len;
        n++;
        if (!cut) break;
        p = cut + 4;
    }
    rp_scene_data s;
    char err[512];
    bool ok = n > 0 && io_load_memory(files, (size_t)n, archive, &s, err, sizeof err);
    if (getenv("RP_FUZZ_VERBOSE")) /* to check that seeds load (or fail where they should) */
        fprintf(stderr, "%d files: %s\n", n, ok ? "loaded" : err);
    if (ok) rp_scene_data_free(&s);
    for (int i = 0; i < n; i++) free(files[i].data);
}

#endif
