/* Fuzz harness: OBJ with its material library and a texture (pieces: OBJ, MTL, PPM). */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.obj","m.mtl","t.ppm"};
    fuzz_load(data, size, names, 3, false);
    return 0;
}
