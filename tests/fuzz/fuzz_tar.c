/* Fuzz harness: the tar(.gz) reader (libarchive, entry sizes, path normalization) and the choice
 * of the archive's main scene, then that scene's loader. */
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"mem.tar"};
    fuzz_load(data, size, names, 1, true);
    return 0;
}
