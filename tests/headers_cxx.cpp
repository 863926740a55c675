// The public headers compile as C++11 with -pedantic, and their packet types keep their layout.
#include <raypack.h>
#include <raypack_io.h>
#if __has_include(<raypack_render.h>)
#include <raypack_render.h>
#endif
#include <cstddef>
#include <cstdio>

static_assert(alignof(rp_ray16) == 64, "rp_ray16 is 64-byte aligned");
static_assert(sizeof(rp_ray) == 48, "rp_ray keeps Embree's layout");
static_assert(sizeof(rp_hit) == 32, "rp_hit keeps Embree's layout");
static_assert(offsetof(rp_ray, tfar) == 32, "tfar where Embree has it");
static_assert(sizeof(rp_ray16) == 12 * 16 * 4, "rp_ray16 is 12 arrays of 16");

int main() {
    rp_rayhit rh = {};
    rh.hit.geom_id = RP_INVALID_ID;
    rp_device_desc d = {};
    d.threads = 1;
    std::printf("headers compile as C++ (%u, %d)\n1 passed, 0 failed\n", rh.hit.geom_id == RP_INVALID_ID ? 1u : 0u, d.threads);
    return 0;
}
