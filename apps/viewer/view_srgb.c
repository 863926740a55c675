/* Linear float to 8-bit sRGB, as rp_image_write encodes PNG pixels (src/io/image.c), but by table:
 * the formula's powf per channel would cost the window a sizeable share of a frame. The floats in
 * [0, 1) are cut into buckets by their top 16 bits (exponent and 8 mantissa bits); within a bucket
 * the code rises by at most one (checked when the table is built), so a bucket stores its first
 * code and the bit pattern where the next begins. Positive floats order as their bit patterns. */
#include "viewer.h"

#include <math.h>
#include <string.h>

enum { SRGB_SHIFT = 15, SRGB_BUCKETS = 0x3F800000u >> SRGB_SHIFT }; /* up to 1.0f */

static uint8_t base[SRGB_BUCKETS];
static uint32_t next_at[SRGB_BUCKETS]; /* first bit pattern with code base + 1; UINT32_MAX: none */
static bool exact[SRGB_BUCKETS];       /* false: the bucket jumps by more than one, use the formula */
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
        base[i] = a;
        next_at[i] = UINT32_MAX;
        exact[i] = z <= a + 1;
        if (z != a + 1) continue;
        while (lo < hi) { /* the first pattern whose code is z */
            uint32_t mid = lo + (hi - lo) / 2u;
            if (view_srgb8_formula(from_bits(mid)) >= z) hi = mid;
            else lo = mid + 1u;
        }
        next_at[i] = lo;
    }
    ready = true;
}

uint8_t view_srgb8(float v) {
    if (!(v > 0.0f)) return 0;
    if (v >= 1.0f) return 255;
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    uint32_t i = b >> SRGB_SHIFT;
    if (!exact[i]) return view_srgb8_formula(v);
    return (uint8_t)(base[i] + (b >= next_at[i]));
}
