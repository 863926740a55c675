/* Linear float to 8-bit sRGB, as rp_image_write encodes PNG pixels (src/io/image.c), but by table:
 * the formula's powf per channel would cost the window a sizeable share of a frame. The floats in
 * [2^-13, 1] are cut into buckets by their top 17 bits (exponent and 8 mantissa bits); within a
 * bucket the code rises by at most one (checked when the table is built), so a bucket stores its
 * first code and the bit pattern where the next begins. Positive floats order as their bit patterns.
 * Checked against the formula on every float in [0, 1] (all 1065353217 of them), on NaN and on
 * negative values: no difference. The encoder itself is inline, in viewer.h. */
#include "viewer.h"

#include <math.h>
#include <string.h>

uint32_t view_srgb_table[VIEW_SRGB_BUCKETS];
static bool ready;
bool view_srgb_exact;

uint8_t view_srgb8_formula(float v) {
    /* the writer's encode_srgb8, operation for operation */
    if (!(v > 0.0f)) return 0;
    if (v >= 1.0f) return 255;
    float s = v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
    return (uint8_t)(s * 255.0f + 0.5f);
}

static float from_bits(uint32_t b) {
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

void view_srgb_init(void) {
    if (ready) return;
    bool ok = view_srgb8_formula(from_bits(VIEW_SRGB_LO - 1u)) == 0; /* below the table all is 0 */
    for (uint32_t i = 0; i < VIEW_SRGB_BUCKETS; i++) {
        uint32_t lo = (i + VIEW_SRGB_FIRST) << VIEW_SRGB_SHIFT, hi = lo + (1u << VIEW_SRGB_SHIFT) - 1u;
        uint8_t a = view_srgb8_formula(from_bits(lo)), z = view_srgb8_formula(from_bits(hi > 0x3F800000u ? 0x3F800000u : hi));
        view_srgb_table[i] = (uint32_t)a << 16 | 0x8000u; /* no step in this bucket */
        if (z > a + 1) ok = false;
        if (z != a + 1) continue;
        while (lo < hi) { /* the first pattern whose code is z */
            uint32_t mid = lo + (hi - lo) / 2u;
            if (view_srgb8_formula(from_bits(mid)) >= z) hi = mid;
            else lo = mid + 1u;
        }
        view_srgb_table[i] = (uint32_t)a << 16 | (lo & 0x7FFFu);
    }
    /* a libm whose powf made the code jump by two within a bucket: every value by the formula */
    view_srgb_exact = ok;
    ready = true;
}
