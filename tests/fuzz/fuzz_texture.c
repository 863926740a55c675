/* Fuzz harness: texture and image decoding. The input is, in turn: the texture a fixed OBJ+MTL maps
 * onto its triangle (PPM P3/P6 by hand, PNG, JPEG and stb_image's other formats by their magic),
 * then, when it starts with their magic, a Radiance HDR file (rp_image_read_hdr: environment maps)
 * or a PFM file (rp_image_read_pfm), read from a memory file (memfd) under /proc/self/fd. EXR is
 * only written by raypack, never read. */
#define _GNU_SOURCE
#include <sys/mman.h>
#include <unistd.h>

#include "fuzz.h"

/* The input as a file: one memfd for the whole run, rewritten per input; NULL when there is none. */
static const char *as_file(const uint8_t *data, size_t size) {
    static int fd = -2;
    static char path[64];
    if (fd == -2) {
        fd = memfd_create("fuzz_texture", MFD_CLOEXEC);
        snprintf(path, sizeof path, "/proc/self/fd/%d", fd);
    }
    if (fd < 0 || ftruncate(fd, 0) != 0 || (size && pwrite(fd, data, size, 0) != (ssize_t)size)) return NULL;
    return path;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.obj", "m.mtl", "t.png"};
    static const char obj[] = "mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                              "f 1/1 2/2 3/3\n";
    static const char mtl[] = "newmtl a\nKd 1 1 1\nmap_Kd t.png\n";
    size_t a = sizeof obj - 1, b = sizeof mtl - 1;
    uint8_t *joined = malloc(a + b + 8 + size);
    if (!joined) return 0;
    memcpy(joined, obj, a);
    memcpy(joined + a, FUZZ_SPLIT, 4);
    memcpy(joined + a + 4, mtl, b);
    memcpy(joined + a + 4 + b, FUZZ_SPLIT, 4);
    if (size) memcpy(joined + a + b + 8, data, size);
    fuzz_load(joined, a + b + 8 + size, names, 3, false);
    free(joined);

    /* both readers stop at the magic of another format: only inputs that have theirs are written
     * out (the texture path above stays as fast as before) */
    bool hdr = size >= 2 && data[0] == '#' && data[1] == '?';
    bool pfm = size >= 2 && data[0] == 'P' && (data[1] == 'F' || data[1] == 'f');
    const char *path = hdr || pfm ? as_file(data, size) : NULL;
    if (path) {
        char err[512];
        int w, h, c;
        float *px = hdr ? rp_image_read_hdr(path, &w, &h, err, sizeof err)
                        : rp_image_read_pfm(path, &w, &h, &c, err, sizeof err);
        if (getenv("RP_FUZZ_VERBOSE")) fprintf(stderr, "%s: %s\n", hdr ? "hdr" : "pfm", px ? "read" : err);
        free(px);
    }
    return 0;
}
