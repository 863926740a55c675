// The public headers compile as C++11 with -pedantic, and their packet types keep their alignment.
#include <raypack.h>
#include <raypack_io.h>
#if __has_include(<raypack_render.h>)
#include <raypack_render.h>
#endif
#include <cstdio>

static_assert(alignof(rp_ray16) == 64, "rp_ray16 is 64-byte aligned");
static_assert(sizeof(rp_ray) == 48, "rp_ray keeps Embree's layout");
static_assert(sizeof(rp_hit) == 32, "rp_hit keeps Embree's layout");

int main() {
    std::printf("%s\n", rp_error_string == nullptr ? "?" : "headers compile as C++");
    std::printf("1 passed, 0 failed\n");
    return 0;
}
