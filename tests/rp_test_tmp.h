/* Files a test writes into its scratch folder (RP_TEST_TMP, set by CTest; else a /tmp default). */
#ifndef RP_TEST_TMP_H
#define RP_TEST_TMP_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static char tmp_dir[512];

/* Makes the folder: RP_TEST_TMP, or fallback when it is not set. */
static inline void tmp_init(const char *fallback) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp_dir, sizeof tmp_dir, "%s", t ? t : fallback);
    mkdir(tmp_dir, 0755);
}

static inline const char *tmp_path(const char *name, char *buf, size_t size) {
    snprintf(buf, size, "%s/%s", tmp_dir, name);
    return buf;
}

/* Writes the file or ends the test. */
static inline void write_bytes(const char *name, const void *data, size_t n) {
    char path[1024];
    FILE *f = fopen(tmp_path(name, path, sizeof path), "wb");
    if (!f) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(1);
    }
    fwrite(data, 1, n, f);
    fclose(f);
}

static inline void write_text(const char *name, const char *text) { write_bytes(name, text, strlen(text)); }
#endif
