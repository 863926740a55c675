/* Fuzz harness: MTL material libraries, the input being the library a fixed OBJ names (and a
 * second piece, if any, the texture its maps may name). */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.obj", "m.mtl", "t.ppm"};
    static const char obj[] = "mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                              "f 1/1 2/2 3/3\nusemtl b\nf 3 2 1\n";
    /* the OBJ first, then the input split into MTL and texture */
    size_t n = sizeof obj - 1;
    uint8_t *joined = malloc(n + 4 + size);
    if (!joined) return 0;
    memcpy(joined, obj, n);
    memcpy(joined + n, FUZZ_SPLIT, 4);
    if (size) memcpy(joined + n + 4, data, size);
    fuzz_load(joined, n + 4 + size, names, 3, false);
    free(joined);
    return 0;
}
