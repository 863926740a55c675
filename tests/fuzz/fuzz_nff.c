/* Fuzz harness: NFF (SPD), with one include. */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"s.nff","b.nff"};
    fuzz_load(data, size, names, 2, false);
    return 0;
}
