/* Fuzz harness: glTF 2.0 through assimp (io_assimp.c). assimp reads files by name only, so the
 * input's pieces (split at "%%" lines, fuzz.h) are written to a folder of this process under
 * $TMPDIR (else /tmp): the scene (s.gltf, or s.glb when it starts with glTF's binary magic), then
 * b.bin (an external buffer) and t.png (an image) it may name; then rp_scene_data_load reads it as
 * the CLI would. Pieces an input lacks are removed, so each run sees only its own files. */
#include <sys/stat.h>
#include <unistd.h>

#include "fuzz.h"

static char dir[256];

static void remove_dir(void) {
    static const char *const all[] = {"s.gltf", "s.glb", "b.bin", "t.png"};
    char p[512];
    for (int i = 0; i < 4; i++) {
        snprintf(p, sizeof p, "%s/%s", dir, all[i]);
        unlink(p);
    }
    rmdir(dir);
}

static bool write_piece(const char *name, const char *data, size_t size) {
    char p[512];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    FILE *f = fopen(p, "wb");
    if (!f) return false;
    bool ok = size == 0 || fwrite(data, 1, size, f) == size;
    return fclose(f) == 0 && ok;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (!dir[0]) {
        const char *t = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/rp_fuzz_gltf_%ld", t && *t ? t : "/tmp", (long)getpid());
        if (mkdir(dir, 0700) != 0) return 0;
        atexit(remove_dir);
    }
    remove_dir();
    if (mkdir(dir, 0700) != 0) return 0;
    bool glb = size >= 4 && memcmp(data, "glTF", 4) == 0;
    const char *names[] = {glb ? "s.glb" : "s.gltf", "b.bin", "t.png"};
    /* a binary scene is one piece: its chunks may hold "%%" lines */
    int count = glb ? 1 : 3, n = 0;
    const char *p = (const char *)data, *end = p + size;
    while (n < count) {
        const char *cut = NULL;
        if (n + 1 < count)
            for (const char *q = p; q + 4 <= end; q++)
                if (memcmp(q, FUZZ_SPLIT, 4) == 0) {
                    cut = q;
                    break;
                }
        const char *stop = cut ? cut + 1 : end;
        if (!write_piece(names[n], p, (size_t)(stop - p))) return 0;
        n++;
        if (!cut) break;
        p = cut + 4;
    }
    char path[512], err[512];
    snprintf(path, sizeof path, "%s/%s", dir, names[0]);
    rp_scene_data s;
    bool ok = rp_scene_data_load(path, &s, err, sizeof err);
    if (getenv("RP_FUZZ_VERBOSE")) fprintf(stderr, "%d files: %s\n", n, ok ? "loaded" : err);
    if (ok) rp_scene_data_free(&s);
    return 0;
}
