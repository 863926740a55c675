/* Fuzz harness: texture decoding (PPM P3/P6 by hand, PNG, JPEG and stb_image's other formats by
 * their magic), the input being the texture a fixed OBJ+MTL maps onto its triangle. */
#include "fuzz.h"

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
    return 0;
}
