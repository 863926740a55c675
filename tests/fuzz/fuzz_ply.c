/* Fuzz harness: PLY, ASCII and binary (the format line decides). */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.ply"};
    fuzz_load(data, size, names, 1, false);
    return 0;
}
