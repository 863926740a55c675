/* Film: exposure and tone mapping of linear radiance for 8-bit images (accumulation itself is the
 * tile renderer's: linear float, the mean of a frame's samples per pixel). */
#include "render.h"

static float aces(float x) {
    /* Narkowicz 2015, "ACES Filmic Tone Mapping Curve": a fit of the ACES RRT + ODT. */
    const float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
    float y = (x * (a * x + b)) / (x * (c * x + d) + e);
    return y < 0.0f ? 0.0f : (y > 1.0f ? 1.0f : y);
}

void rp_film_tonemap(float *pixels, size_t count, int channels, float exposure, rp_tonemap tonemap) {
    float scale = exp2f(exposure);
    size_t n = count * (size_t)channels;
    for (size_t i = 0; i < n; i++) {
        float v = pixels[i] * scale;
        if (!(v > 0.0f)) v = 0.0f; /* negative and NaN */
        switch (tonemap) {
        case RP_TONEMAP_SRGB: v = v > 1.0f ? 1.0f : v; break;
        case RP_TONEMAP_ACES: v = aces(v); break;
        }
        pixels[i] = v;
    }
}
