/* Minimal test harness: CHECK counts, RP_TEST_END prints "N passed, N failed" for CTest. */
#ifndef RP_TEST_H
#define RP_TEST_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int rp_test_passed_, rp_test_failed_;

#define CHECK(cond)                                                                      \
    do {                                                                                 \
        if (cond) {                                                                      \
            rp_test_passed_++;                                                           \
        } else {                                                                         \
            rp_test_failed_++;                                                           \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);     \
        }                                                                                \
    } while (0)

#define CHECKF(cond, ...)                                                                \
    do {                                                                                 \
        if (cond) {                                                                      \
            rp_test_passed_++;                                                           \
        } else {                                                                         \
            rp_test_failed_++;                                                           \
            fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond);     \
            fprintf(stderr, __VA_ARGS__);                                                \
            fputc('\n', stderr);                                                         \
        }                                                                                \
    } while (0)

#define RP_TEST_END()                                                                    \
    (printf("%d passed, %d failed\n", rp_test_passed_, rp_test_failed_),                 \
     rp_test_failed_ == 0 && rp_test_passed_ > 0 ? 0 : 1)

/* Path of a shared scene, or NULL (with a message) when the folder is missing. */
static inline const char *rp_test_scene(const char *name, char *buf, size_t size) {
    const char *dir = getenv("RP_SCENES");
    if (!dir) dir = "../shared/scenes";
    snprintf(buf, size, "%s/%s", dir, name);
    FILE *f = fopen(buf, "rb");
    if (!f) {
        fprintf(stderr, "scene %s not found\n", buf);
        return NULL;
    }
    fclose(f);
    return buf;
}

/* True when running in the sanitizer build (tests shrink their workloads there). */
static inline int rp_test_sanitized(void) { return getenv("RP_SANITIZED") != NULL; }
#endif
