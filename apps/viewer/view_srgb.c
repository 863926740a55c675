/* Linear float to 8-bit sRGB, as rp_image_write encodes PNG pixels (src/io/image.c), but by table:
 * the formula's powf per channel would cost the window a sizeable share of a frame. The floats in
 * [0, 1) are cut into buckets by their top 16 bits (exponent and 8 mantissa bits); within a bucket
 * the code rises by at most one (checked when the table is built), so a bucket stores its first
 * code and the bit pattern where the next begins. Positive floats order as their bit patterns.
 * Checked against the formula on every float in [0, 1] (all 1065353217 of them): no difference;
 * a bucket that jumped by two would fall back to the formula. */
#include "viewer.h"

#include <math.h>
#include <string.h>

enum { SRGB_SHIFT = 15, SRGB_BUCKETS = 0x3F800000u >> SRGB_SHIFT }; /* up to 1.0f */

/* Per bucket, one word (one load per channel): bits 0-15 where in the bucket (its low 15 bits) the
 * code becomes base + 1 (0x8000: nowhere), bits 16-23 base, bit 31: jumps by more than one, use
 * the formula. */
static uint32_t table[SRGB_BUCKETS];
static bool ready;

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
    for (uint32_t i = 0; i < SRGB_BUCKETS; i++) {
        uint32_t lo = i << SRGB_SHIFT, hi = lo + (1u << SRGB_SHIFT) - 1u;
        uint8_t a = view_srgb8_formula(from_bits(lo)), z = view_srgb8_formula(from_bits(hi));
        table[i] = (uint32_t)a << 16 | 0x8000u;
        if (z > a + 1) table[i] |= 1u << 31;
        if (z != a + 1) continue;
        while (lo < hi) { /* the first pattern whose code is z */
            uint32_t mid = lo + (hi - lo) / 2u;
            if (view_srgb8_formula(from_bits(mid)) >= z) hi = mid;
            else lo = mid + 1u;
        }
        table[i] = (uint32_t)a << 16 | (lo & 0x7FFFu);
    }
    ready = true;
}

uint8_t view_srgb8(float v) {
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    /* as bits: negatives (sign set), NaNs and [1, inf] all lie at or above 1.0f's pattern */
    if (b >= 0x3F800000u) return b <= 0x7F800000u ? 255 : 0;
    uint32_t t = table[b >> SRGB_SHIFT];
    if (t >> 31) return view_srgb8_formula(v);
    return (uint8_t)((t >> 16) + ((b & 0x7FFFu) >= (t & 0xFFFFu)));
}
