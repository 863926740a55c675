// rp-test: timeout=600
/* The viewer's float to 8-bit sRGB conversion (apps/viewer/view_srgb.c, compiled in here so the test
 * builds without SDL2): the table equals the PNG writer's formula at every code's threshold and on
 * every 16th float in [0, 1]; each instruction set's view_srgb_pixels (scalar, AVX2, AVX-512, as the
 * CPU has them) equals the table on every float in [0, 1] (every 31st under sanitizers), on NaN,
 * infinities, negatives and values above 1, and accumulates sum += add, sum * inv bit for bit as
 * the scalar loop does, for row lengths that leave every tail. */
#include <math.h>
#include <stdint.h>

#include "rp_test.h"

#include "../apps/viewer/view_srgb.c"

static float bits_float(uint32_t b) {
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

/* Every code's first float by the formula (binary search on the patterns) and its neighbour below. */
static void test_thresholds(void) {
    int bad = 0;
    for (int c = 1; c < 256; c++) {
        uint32_t lo = 0, hi = 0x3F800000u;
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2u;
            if (view_srgb8_formula(bits_float(mid)) >= c) hi = mid;
            else lo = mid + 1u;
        }
        if (view_srgb8(bits_float(lo)) != (uint32_t)view_srgb8_formula(bits_float(lo)) ||
            view_srgb8(bits_float(lo - 1u)) != (uint32_t)view_srgb8_formula(bits_float(lo - 1u)))
            bad++;
    }
    CHECKF(bad == 0, "%d code thresholds differ from the formula", bad);
    int diff = 0;
    for (uint32_t b = 0; b <= 0x3F800000u; b += 16u)
        if (view_srgb8(bits_float(b)) != (uint32_t)view_srgb8_formula(bits_float(b))) diff++;
    CHECKF(diff == 0, "table and formula differ on %d of the sampled floats", diff);
}

enum { N = 4096 }; /* pixels per batch */

/* Every pattern in [first, last] by stride through each selected instruction set, against view_srgb8. */
static void test_isa(int isa, uint32_t stride) {
    const char *name = view_srgb_select(isa);
    static float in[3 * N], work[3 * N];
    static uint32_t out[N];
    size_t wrong = 0, checked = 0;
    uint32_t b = 0;
    bool done = false;
    while (!done) {
        int n = 0;
        for (; n < 3 * N && !done; n++) {
            in[n] = bits_float(b);
            if (b >= 0x3F800000u - stride) done = true;
            else b += stride;
        }
        while (n % 3) in[n++] = 1.0f;
        memcpy(work, in, (size_t)n * sizeof(float));
        view_srgb_pixels(work, NULL, 1.0f, out, n / 3);
        for (int i = 0; i < n / 3; i++) {
            uint32_t want = 0xFF000000u | view_srgb8(in[3 * i]) << 16 | view_srgb8(in[3 * i + 1]) << 8 |
                            view_srgb8(in[3 * i + 2]);
            wrong += out[i] != want;
        }
        checked += (size_t)n;
    }
    CHECKF(wrong == 0 && checked > 1000000, "%s: %zu of %zu pixels differ from the table", name, wrong, checked);

    /* specials, and sums of two frames averaged, for every row length up to 40 (each tail) */
    const float special[] = {NAN, -NAN, INFINITY, -INFINITY, -1.0f, -0.0f, 0.0f, 1.0f, 1.0000001f, 2.0f, 1e30f,
                             1e-40f, 3e-39f, 0.0031308f, 0.5f, 0.99999994f, 7.0e-5f, 1.5e-4f, 0.2140f, 0.04045f};
    size_t ns = sizeof special / sizeof special[0];
    uint32_t seed = 12345u;
    wrong = 0;
    for (int n = 1; n <= 40; n++) {
        static float sum[3 * 40], sum_ref[3 * 40], add[3 * 40];
        for (int i = 0; i < 3 * n; i++) {
            seed = seed * 1664525u + 1013904223u;
            sum[i] = (seed >> 8) % 4u == 0 ? special[(seed >> 12) % ns] : (float)(seed >> 8) * 0x1p-23f;
            seed = seed * 1664525u + 1013904223u;
            add[i] = (seed >> 8) % 5u == 0 ? special[(seed >> 12) % ns] : (float)(seed >> 8) * 0x1p-24f;
        }
        memcpy(sum_ref, sum, sizeof sum);
        float inv = 1.0f / (float)(n % 7 + 1);
        view_srgb_pixels(sum, add, inv, out, n);
        for (int i = 0; i < n; i++) {
            uint32_t want = 0xFF000000u;
            for (int k = 0; k < 3; k++) {
                sum_ref[3 * i + k] += add[3 * i + k];
                want |= view_srgb8(sum_ref[3 * i + k] * inv) << (16 - 8 * k);
            }
            wrong += out[i] != want;
        }
        /* the same sums, bit for bit (a NaN's sign and payload aside: which operand's NaN an add
         * returns is the compiler's choice) */
        for (int i = 0; i < 3 * n; i++)
            wrong += !(isnan(sum[i]) && isnan(sum_ref[i])) && memcmp(&sum[i], &sum_ref[i], sizeof(float)) != 0;
    }
    CHECKF(wrong == 0, "%s: %zu differences when accumulating", name, wrong);

    /* rectangles (view_srgb_rect: a tile's rows in one call) inside wider rows: each row as alone,
     * the floats and words between rows untouched */
    wrong = 0;
    for (int rows = 1; rows <= 5; rows++)
        for (int n = 1; n <= 40; n += 3) {
            enum { SW = 3 * 48, OW = 45 };
            static float rsum[5 * SW], rref[5 * SW], radd[5 * SW];
            static uint32_t rout[5 * OW];
            for (int i = 0; i < rows * SW; i++) {
                seed = seed * 1664525u + 1013904223u;
                rsum[i] = (float)(seed >> 8) * 0x1p-24f;
                seed = seed * 1664525u + 1013904223u;
                radd[i] = (seed >> 8) % 5u == 0 ? special[(seed >> 12) % ns] : (float)(seed >> 8) * 0x1p-25f;
            }
            memcpy(rref, rsum, sizeof rsum);
            for (int i = 0; i < 5 * OW; i++) rout[i] = 0x12345678u;
            float inv = 1.0f / (float)(rows + 1);
            bool with_add = (n + rows) % 2 == 0;
            view_srgb_rect(rsum, with_add ? radd : NULL, SW, inv, rout, OW, n, rows);
            for (int y = 0; y < rows; y++) {
                for (int i = 0; i < OW; i++) {
                    uint32_t want = 0x12345678u;
                    if (i < n) {
                        want = 0xFF000000u;
                        for (int k = 0; k < 3; k++) {
                            float *r = &rref[y * SW + 3 * i + k];
                            if (with_add) *r += radd[y * SW + 3 * i + k];
                            want |= view_srgb8(*r * inv) << (16 - 8 * k);
                        }
                    }
                    wrong += rout[y * OW + i] != want;
                }
                for (int i = 0; i < SW; i++) {
                    float a = rsum[y * SW + i], r = rref[y * SW + i];
                    wrong += !(isnan(a) && isnan(r)) && memcmp(&a, &r, sizeof a) != 0;
                }
            }
        }
    CHECKF(wrong == 0, "%s: %zu differences in rectangles", name, wrong);
    printf("%s: %zu floats checked\n", name, checked);
}

int main(void) {
    view_srgb_init();
    CHECKF(view_srgb_exact, "the table could not be built (libm's powf steps by two within a float's ulp)");
    printf("table: %d words\n", view_srgb_table_words());
    test_thresholds();
    uint32_t stride = rp_test_sanitized() ? 31u : 1u;
    /* 1: scalar; 8: AVX2 and 16: AVX-512 where the CPU has them (select says which ran) */
    const char *last = "";
    static const int isas[] = {1, 8, 16};
    for (size_t i = 0; i < sizeof isas / sizeof isas[0]; i++) {
        const char *name = view_srgb_select(isas[i]);
        if (strcmp(name, last) == 0) continue;
        last = name;
        test_isa(isas[i], stride);
    }
    return RP_TEST_END();
}
