/* Fuzz harness: BART AFF with includes (b, c) and a texture. */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.aff","b.aff","c.aff","t.ppm"};
    fuzz_load(data, size, names, 4, false);
    return 0;
}
