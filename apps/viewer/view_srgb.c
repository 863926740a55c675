/* Linear float to 8-bit sRGB, as rp_image_write encodes PNG pixels (src/io/image.c), but by table:
 * the formula's powf per channel would cost the window a sizeable share of a frame. The floats in
 * [2^-13, 1] are cut into buckets by exponent and, per octave, as few top mantissa bits as keep the
 * code rising by at most one within a bucket (found when the table is built: 0 to 7 bits, 384
 * buckets in all), so a bucket stores its first code and the bit pattern where the next begins.
 * Positive floats order as their bit patterns.
 * Checked against the formula on every float in [0, 1] (all 1065353217 of them), on NaN and on
 * negative values: no difference. The encoder itself is inline, in viewer.h. Whole rows go through
 * view_srgb_pixels (a tile's rows through view_srgb_rect, the constants set up once a tile), which
 * also adds a frame into the accumulated sum: the same lookup on 8 (AVX2) or 16 (AVX-512) lanes
 * with a gather (the octave's shift and first bucket come from a register), chosen once by the CPU
 * (test_view_srgb checks each against the table on every float in [0, 1]). The gathers were most of
 * the cost: 1.2-1.6 ms of CPU a 1024x768 frame on the EPYC (Zen 4) test machine, 2-3 ms inside the
 * viewer, where the rendering between tiles evicts the table. AVX-512, and AVX2 with FMA,
 * therefore compute the code by a polynomial and gather only for lanes near a code's edge (about
 * 0.1% of them): 25-30% less CPU on the same frame (AVX-512, Zen 4), and nothing for the rendering
 * to evict. On Zen 3 (AVX2), whose gathers are slower still, the polynomial and the codes packed in
 * registers took the conversion from 11.9% to 4.7% of the viewer's samples (cornell_box). */
#include "viewer.h"

#include <math.h>
#include <string.h>

uint32_t view_srgb_table[VIEW_SRGB_MAX];
uint32_t view_srgb_shift[16], view_srgb_first[16];
static float view_srgb_pow2[16]; /* 2^((e - 13) / 2.4) for octave e */
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

/* Whether octave e cut into 2^k buckets has the code rise by at most one within each. */
static bool octave_fits(uint32_t e, uint32_t k) {
    uint32_t base = (e + (uint32_t)VIEW_SRGB_E0) << 23, w = 1u << (23 - k);
    for (uint32_t j = 0; j < (1u << k); j++) {
        uint32_t lo = base + j * w;
        if (view_srgb8_formula(from_bits(lo + w - 1u)) > view_srgb8_formula(from_bits(lo)) + 1) return false;
    }
    return true;
}

void view_srgb_init(void) {
    if (ready) return;
    bool ok = view_srgb8_formula(from_bits(VIEW_SRGB_LO)) == 0; /* below the table all is 0 */
    uint32_t n = 0;
    for (uint32_t e = 0; e < 16 && ok; e++) {
        uint32_t k = 0; /* octave 13 is 1.0 alone, 14 and 15 never used */
        while (e < VIEW_SRGB_OCTAVES - 1 && k < 16 && !octave_fits(e, k)) k++;
        view_srgb_shift[e] = 23 - k;
        view_srgb_first[e] = n;
        if (e >= VIEW_SRGB_OCTAVES) continue;
        if (n + (1u << k) > VIEW_SRGB_MAX || k == 16) {
            ok = false;
            break;
        }
        uint32_t base = (e + (uint32_t)VIEW_SRGB_E0) << 23, w = 1u << (23 - k);
        for (uint32_t j = 0; j < (1u << k); j++, n++) {
            uint32_t lo = base + j * w, hi = lo + w - 1u;
            if (e == VIEW_SRGB_OCTAVES - 1) hi = lo; /* 1.0 */
            uint8_t a = view_srgb8_formula(from_bits(lo)), z = view_srgb8_formula(from_bits(hi));
            view_srgb_table[n] = (uint32_t)a << 24 | 1u << 23; /* no step in this bucket */
            if (z != a + 1) continue;
            while (lo < hi) { /* the first pattern whose code is z */
                uint32_t mid = lo + (hi - lo) / 2u;
                if (view_srgb8_formula(from_bits(mid)) >= z) hi = mid;
                else lo = mid + 1u;
            }
            view_srgb_table[n] = (uint32_t)a << 24 | (lo & (w - 1u));
        }
    }
    for (int e = 0; e < 16; e++) view_srgb_pow2[e] = (float)pow(2.0, (double)(e - 13) / 2.4);
    /* a libm whose powf made the code jump by two within a float's ulp: every value by the formula */
    view_srgb_exact = ok;
    ready = true;
}

/* The table's size in words, for reports. */
int view_srgb_table_words(void) { return (int)view_srgb_first[VIEW_SRGB_OCTAVES]; }

/* ---- whole rows: accumulate, average and encode, per instruction set ---- */

static uint32_t pixel_scalar(const float *c) {
    return 0xFF000000u | view_srgb8(c[0]) << 16 | view_srgb8(c[1]) << 8 | view_srgb8(c[2]);
}

/* The reference for the others: per channel sum += add, then the code of sum * inv. */
static void row_scalar(float *sum, const float *add, float inv, uint32_t *out, int n) {
    for (int i = 0; i < n; i++) {
        float c[3];
        for (int k = 0; k < 3; k++) {
            if (add) sum[3 * i + k] += add[3 * i + k];
            c[k] = sum[3 * i + k] * inv;
        }
        out[i] = pixel_scalar(c);
    }
}

/* A rectangle's rows: sum and add advance by stride floats a row, out by pitch words. */
static void pixels_scalar(float *sum, const float *add, size_t stride, float inv, uint32_t *out, size_t pitch, int n,
                          int rows) {
    for (int y = 0; y < rows; y++, sum += stride, add = add ? add + stride : NULL, out += pitch)
        row_scalar(sum, add, inv, out, n);
}

#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define VIEW_SRGB_X86 1

/* x^(1/2.4) for x in [1, 2) as a polynomial in t = 2x - 3, highest degree first (codes16_poly). */
static const float SRGB_POLY[8] = {1.149400295e-05f, -4.286558067e-05f, 1.435515284e-04f, -6.016229575e-04f,
                                   2.812993774e-03f, -1.598916955e-02f, 1.644518801e-01f,  1.184053612e+00f};

/* The table lookup of view_srgb8 on 8 lanes: clamp (max first: NaN becomes 2^-13), the octave's
 * shift and first bucket from registers (octaves 8-13 from the second half), gather. */
__attribute__((target("avx2"))) static inline __m256i codes8(__m256 v, __m256i sh0, __m256i sh1, __m256i f0,
                                                             __m256i f1) {
    v = _mm256_min_ps(_mm256_max_ps(v, _mm256_set1_ps(0x1p-13f)), _mm256_set1_ps(1.0f));
    __m256i b = _mm256_castps_si256(v);
    __m256i e = _mm256_sub_epi32(_mm256_srli_epi32(b, 23), _mm256_set1_epi32(VIEW_SRGB_E0));
    __m256i m = _mm256_and_si256(b, _mm256_set1_epi32(0x7FFFFF));
    __m256i hi = _mm256_cmpgt_epi32(e, _mm256_set1_epi32(7));
    __m256i sh = _mm256_blendv_epi8(_mm256_permutevar8x32_epi32(sh0, e), _mm256_permutevar8x32_epi32(sh1, e), hi);
    __m256i first = _mm256_blendv_epi8(_mm256_permutevar8x32_epi32(f0, e), _mm256_permutevar8x32_epi32(f1, e), hi);
    __m256i i = _mm256_add_epi32(first, _mm256_srlv_epi32(m, sh));
    __m256i t = _mm256_i32gather_epi32((const int *)view_srgb_table, i, 4);
    __m256i ones = _mm256_set1_epi32(1);
    __m256i low = _mm256_and_si256(m, _mm256_sub_epi32(_mm256_sllv_epi32(ones, sh), ones));
    __m256i below = _mm256_cmpgt_epi32(_mm256_and_si256(t, _mm256_set1_epi32(0xFFFFFF)), low); /* -1: no step */
    __m256i c = _mm256_srli_epi32(t, 24);
    return _mm256_add_epi32(_mm256_add_epi32(c, _mm256_set1_epi32(1)), below);
}

/* codes16_poly (below) on 8 lanes, for AVX2 with FMA: the table's gather takes only the lanes
 * within 5e-4 of a code's edge. Gathers are slow on some AVX2 processors (Zen 2 and 3: `perf` had
 * the table's conversion at 12% of the viewer's samples on cornell_box, Zen 3). */
__attribute__((target("avx2,fma"))) static inline __m256i codes8_poly(__m256 v, __m256 pow2lo, __m256 pow2hi,
                                                                      __m256i sh0, __m256i sh1, __m256i f0,
                                                                      __m256i f1) {
    __m256 c = _mm256_min_ps(_mm256_max_ps(v, _mm256_set1_ps(0x1p-13f)), _mm256_set1_ps(1.0f));
    __m256i b = _mm256_castps_si256(c);
    __m256 x = _mm256_castsi256_ps(
        _mm256_or_si256(_mm256_and_si256(b, _mm256_set1_epi32(0x7FFFFF)), _mm256_set1_epi32(0x3F800000)));
    __m256 t = _mm256_fmadd_ps(x, _mm256_set1_ps(2.0f), _mm256_set1_ps(-3.0f)); /* exact */
    __m256 g = _mm256_set1_ps(SRGB_POLY[0]);
    for (int k = 1; k < 8; k++) g = _mm256_fmadd_ps(g, t, _mm256_set1_ps(SRGB_POLY[k]));
    /* 2^(e/2.4) for octave e = 0..13: a permute of each half of the 16 entries, by e's bit 3 */
    __m256i e = _mm256_sub_epi32(_mm256_srli_epi32(b, 23), _mm256_set1_epi32(VIEW_SRGB_E0));
    __m256 hi = _mm256_castsi256_ps(_mm256_cmpgt_epi32(e, _mm256_set1_epi32(7)));
    __m256 p2 = _mm256_blendv_ps(_mm256_permutevar8x32_ps(pow2lo, e), _mm256_permutevar8x32_ps(pow2hi, e), hi);
    __m256 y = _mm256_fmadd_ps(_mm256_mul_ps(g, p2), _mm256_set1_ps(269.025f), _mm256_set1_ps(-13.525f));
    __m256 r = _mm256_sub_ps(y, _mm256_round_ps(y, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC));
    __m256 edge = _mm256_cmp_ps(_mm256_andnot_ps(_mm256_set1_ps(-0.0f), r), _mm256_set1_ps(5e-4f), _CMP_LT_OQ);
    __m256 lin = _mm256_cmp_ps(c, _mm256_set1_ps(0.0031308f), _CMP_LE_OQ);
    if (_mm256_movemask_ps(lin)) { /* the formula's own operations where some lane is that dark */
        __m256 yl = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(c, _mm256_set1_ps(12.92f)), _mm256_set1_ps(255.0f)),
                                  _mm256_set1_ps(0.5f));
        y = _mm256_blendv_ps(y, yl, lin);
        edge = _mm256_andnot_ps(lin, edge);
    }
    __m256i code = _mm256_cvttps_epi32(y);
    if (_mm256_movemask_ps(edge))
        code = _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(code),
                                                    _mm256_castsi256_ps(codes8(v, sh0, sh1, f0, f1)), edge));
    return code;
}

/* 8 pixels' codes, channels interleaved as the floats were (c0: R0 G0 B0 R1 G1 B1 R2 G2, c1, c2), to
 * 8 xRGB8888 words in registers (as xrgb16): packed to bytes, the 24 in order in the low half and
 * bytes 8-23 in the high one, then one byte shuffle per half. Codes stored as bytes and reloaded
 * 12 apart (as this routine did before) stall on store forwarding: `perf annotate` put half of
 * the conversion's samples on that reload (Zen 3). */
__attribute__((target("avx2"))) static inline __m256i xrgb8(__m256i c0, __m256i c1, __m256i c2) {
    /* per 128-bit half: [c0 0-3, c1 0-3, c2 0-3, c2 0-3] and [c0 4-7, c1 4-7, c2 4-7, c2 4-7] */
    __m256i b = _mm256_packus_epi16(_mm256_packus_epi32(c0, c1), _mm256_packus_epi32(c2, c2));
    b = _mm256_permutevar8x32_epi32(b, _mm256_setr_epi32(0, 4, 1, 5, 1, 5, 2, 6));
    const __m256i order = _mm256_setr_epi8(2, 1, 0, -1, 5, 4, 3, -1, 8, 7, 6, -1, 11, 10, 9, -1, /* pixels 0-3 */
                                           6, 5, 4, -1, 9, 8, 7, -1, 12, 11, 10, -1, 15, 14, 13, -1); /* 4-7 */
    return _mm256_or_si256(_mm256_shuffle_epi8(b, order), _mm256_set1_epi32((int)0xFF000000u));
}

__attribute__((target("avx2,fma"))) static void pixels_avx2(float *sum, const float *add, size_t stride, float inv,
                                                            uint32_t *out, size_t pitch, int n, int rows) {
    const __m256 s = _mm256_set1_ps(inv);
    const __m256i sh0 = _mm256_loadu_si256((const __m256i *)view_srgb_shift),
                  sh1 = _mm256_loadu_si256((const __m256i *)(view_srgb_shift + 8)),
                  f0 = _mm256_loadu_si256((const __m256i *)view_srgb_first),
                  f1 = _mm256_loadu_si256((const __m256i *)(view_srgb_first + 8));
    const __m256 pow2lo = _mm256_loadu_ps(view_srgb_pow2), pow2hi = _mm256_loadu_ps(view_srgb_pow2 + 8);
    for (int y = 0; y < rows; y++, sum += stride, add = add ? add + stride : NULL, out += pitch) {
        int i = 0;
        for (; i + 8 <= n; i += 8) { /* 8 pixels: 24 floats, 3 vectors */
            float *p = sum + 3 * i;
            __m256 v0 = _mm256_loadu_ps(p), v1 = _mm256_loadu_ps(p + 8), v2 = _mm256_loadu_ps(p + 16);
            if (add) {
                const float *a = add + 3 * i;
                v0 = _mm256_add_ps(v0, _mm256_loadu_ps(a));
                v1 = _mm256_add_ps(v1, _mm256_loadu_ps(a + 8));
                v2 = _mm256_add_ps(v2, _mm256_loadu_ps(a + 16));
                _mm256_storeu_ps(p, v0);
                _mm256_storeu_ps(p + 8, v1);
                _mm256_storeu_ps(p + 16, v2);
            }
            __m256i c0 = codes8_poly(_mm256_mul_ps(v0, s), pow2lo, pow2hi, sh0, sh1, f0, f1);
            __m256i c1 = codes8_poly(_mm256_mul_ps(v1, s), pow2lo, pow2hi, sh0, sh1, f0, f1);
            __m256i c2 = codes8_poly(_mm256_mul_ps(v2, s), pow2lo, pow2hi, sh0, sh1, f0, f1);
            _mm256_storeu_si256((__m256i *)(out + i), xrgb8(c0, c1, c2));
        }
        row_scalar(sum + 3 * i, add ? add + 3 * i : NULL, inv, out + i, n - i);
    }
}

__attribute__((target("avx512f,avx2"))) static inline __m512i codes16(__m512 v, __m512i shift, __m512i first) {
    v = _mm512_min_ps(_mm512_max_ps(v, _mm512_set1_ps(0x1p-13f)), _mm512_set1_ps(1.0f));
    __m512i b = _mm512_castps_si512(v);
    __m512i e = _mm512_sub_epi32(_mm512_srli_epi32(b, 23), _mm512_set1_epi32(VIEW_SRGB_E0));
    __m512i m = _mm512_and_si512(b, _mm512_set1_epi32(0x7FFFFF));
    __m512i sh = _mm512_permutexvar_epi32(e, shift);
    __m512i i = _mm512_add_epi32(_mm512_permutexvar_epi32(e, first), _mm512_srlv_epi32(m, sh));
    __m512i t = _mm512_i32gather_epi32(i, (const int *)view_srgb_table, 4);
    __m512i ones = _mm512_set1_epi32(1);
    __m512i low = _mm512_and_si512(m, _mm512_sub_epi32(_mm512_sllv_epi32(ones, sh), ones));
    __mmask16 step = _mm512_cmpge_epi32_mask(low, _mm512_and_si512(t, _mm512_set1_epi32(0xFFFFFF)));
    __m512i c = _mm512_srli_epi32(t, 24);
    return _mm512_mask_add_epi32(c, step, c, _mm512_set1_epi32(1));
}

/* The codes of 16 values without the table where that is safe. The formula's linear part is the
 * formula's own operations. Its power part, 1.055 v^(1/2.4) - 0.055, is v = 2^e x with x in [1, 2):
 * 2^(e/2.4) from a register and x^(1/2.4) by a degree-7 polynomial (Chebyshev interpolation in
 * t = 2x - 3, relative error 4e-8); where the value lands within 5e-4 of a code's edge, where the
 * error could matter, the lane takes the table's code. With float rounding the polynomial's code
 * and the formula's differ only within 1e-5 to 5e-5 of an edge (test_view_srgb fails with a band
 * of 1e-5, passes with 5e-5 on every float in [0, 1]): 5e-4 leaves a tenfold margin for another
 * libm's powf, and sends about 0.1% of lanes to the table (2e-3 sent 0.4%, and the gathers were a
 * quarter of the conversion's time). */
__attribute__((target("avx512f,avx512dq,avx2,fma"))) static inline __m512i codes16_poly(__m512 v, __m512 pow2,
                                                                                         __m512i shift, __m512i first) {
    __m512 c = _mm512_min_ps(_mm512_max_ps(v, _mm512_set1_ps(0x1p-13f)), _mm512_set1_ps(1.0f));
    __m512i b = _mm512_castps_si512(c);
    /* x = the mantissa as a float in [1, 2): (b & 0x7FFFFF) | 0x3F800000 in one ternary op */
    __m512 x = _mm512_castsi512_ps(
        _mm512_ternarylogic_epi32(b, _mm512_set1_epi32(0x7FFFFF), _mm512_set1_epi32(0x3F800000), 0xEA));
    __m512 t = _mm512_fmadd_ps(x, _mm512_set1_ps(2.0f), _mm512_set1_ps(-3.0f)); /* exact */
    __m512 g = _mm512_set1_ps(SRGB_POLY[0]);
    for (int k = 1; k < 8; k++) g = _mm512_fmadd_ps(g, t, _mm512_set1_ps(SRGB_POLY[k]));
    /* pow2 is indexed by the exponent field's low 4 bits (the permute reads no more): pixels_avx512
     * rotated it so, which saves subtracting the first octave's exponent */
    __m512 p = _mm512_mul_ps(g, _mm512_permutexvar_ps(_mm512_srli_epi32(b, 23), pow2));
    /* (1.055 p - 0.055) 255 + 0.5; at most 255.5 (v = 1), so the truncated code is at most 255 */
    __m512 y = _mm512_fmadd_ps(p, _mm512_set1_ps(269.025f), _mm512_set1_ps(-13.525f));
    /* the code changes where y crosses an integer: y near one is an edge */
    __m512 r = _mm512_reduce_ps(y, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    __mmask16 edge = _mm512_cmp_ps_mask(_mm512_abs_ps(r), _mm512_set1_ps(5e-4f), _CMP_LT_OQ);
    /* the linear part as the formula computes it: (12.92 v) 255 + 0.5, then truncated; only where
     * some lane is that dark */
    __mmask16 lin = _mm512_cmp_ps_mask(c, _mm512_set1_ps(0.0031308f), _CMP_LE_OQ);
    if (lin) {
        __m512 yl = _mm512_add_ps(_mm512_mul_ps(_mm512_mul_ps(c, _mm512_set1_ps(12.92f)), _mm512_set1_ps(255.0f)),
                                  _mm512_set1_ps(0.5f));
        y = _mm512_mask_mov_ps(y, lin, yl);
        edge &= (__mmask16)~lin;
    }
    __m512i code = _mm512_cvttps_epi32(y);
    if (edge) code = _mm512_mask_mov_epi32(code, edge, codes16(v, shift, first));
    return code;
}

/* 16 pixels' codes, channels interleaved as the floats were (c0: R0 G0 B0 R1 .., c2: .. B15), to
 * 16 xRGB8888 words, in registers: each channel gathered by a two-source permute, the lanes past
 * the 32nd from c2. (Bytes stored and reloaded 12 apart would stall on store forwarding.) */
__attribute__((target("avx512f,avx2"))) static inline __m512i xrgb16(__m512i c0, __m512i c1, __m512i c2) {
    const __m512i r = _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 33, 36, 39, 42, 45);
    const __m512i one = _mm512_set1_epi32(1), two = _mm512_set1_epi32(2);
    __m512i g = _mm512_add_epi32(r, one), b = _mm512_add_epi32(r, two);
    /* lanes whose channel lies in c2 (index 32 and up): R from pixel 11, G from 11, B from 10 */
    __m512i R = _mm512_mask_permutexvar_epi32(_mm512_permutex2var_epi32(c0, r, c1), 0xF800, r, c2);
    __m512i G = _mm512_mask_permutexvar_epi32(_mm512_permutex2var_epi32(c0, g, c1), 0xF800, g, c2);
    __m512i B = _mm512_mask_permutexvar_epi32(_mm512_permutex2var_epi32(c0, b, c1), 0xFC00, b, c2);
    __m512i x = _mm512_or_si512(_mm512_slli_epi32(R, 16), _mm512_slli_epi32(G, 8));
    return _mm512_or_si512(_mm512_or_si512(x, B), _mm512_set1_epi32((int)0xFF000000u));
}

__attribute__((target("avx512f,avx512dq,avx2,fma"))) static void pixels_avx512(float *sum, const float *add, size_t stride,
                                                                  float inv, uint32_t *out, size_t pitch, int n,
                                                                  int rows) {
    const __m512 s = _mm512_set1_ps(inv);
    const __m512i shift = _mm512_loadu_si512(view_srgb_shift), first = _mm512_loadu_si512(view_srgb_first);
    /* octave e's entry at (e + VIEW_SRGB_E0) & 15, where the exponent field's low 4 bits point */
    const __m512i rot = _mm512_and_si512(
        _mm512_sub_epi32(_mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
                         _mm512_set1_epi32(VIEW_SRGB_E0)),
        _mm512_set1_epi32(15));
    const __m512 pow2 = _mm512_permutexvar_ps(rot, _mm512_loadu_ps(view_srgb_pow2));
    for (int y = 0; y < rows; y++, sum += stride, add = add ? add + stride : NULL, out += pitch) {
        int i = 0;
        for (; i + 16 <= n; i += 16) { /* 16 pixels: 48 floats, 3 vectors (named, not an array the
                                          * compiler kept on the stack) */
            float *p = sum + 3 * i;
            __m512 v0 = _mm512_loadu_ps(p), v1 = _mm512_loadu_ps(p + 16), v2 = _mm512_loadu_ps(p + 32);
            if (add) {
                const float *a = add + 3 * i;
                v0 = _mm512_add_ps(v0, _mm512_loadu_ps(a));
                v1 = _mm512_add_ps(v1, _mm512_loadu_ps(a + 16));
                v2 = _mm512_add_ps(v2, _mm512_loadu_ps(a + 32));
                _mm512_storeu_ps(p, v0);
                _mm512_storeu_ps(p + 16, v1);
                _mm512_storeu_ps(p + 32, v2);
            }
            __m512i c0 = codes16_poly(_mm512_mul_ps(v0, s), pow2, shift, first);
            __m512i c1 = codes16_poly(_mm512_mul_ps(v1, s), pow2, shift, first);
            __m512i c2 = codes16_poly(_mm512_mul_ps(v2, s), pow2, shift, first);
            _mm512_storeu_si512(out + i, xrgb16(c0, c1, c2));
        }
        row_scalar(sum + 3 * i, add ? add + 3 * i : NULL, inv, out + i, n - i);
    }
}
#endif

static void (*pixels_fn)(float *, const float *, size_t, float, uint32_t *, size_t, int, int) = pixels_scalar;

const char *view_srgb_select(int isa) {
    pixels_fn = pixels_scalar;
    if (!view_srgb_exact) return "formula";
#ifdef VIEW_SRGB_X86
    __builtin_cpu_init();
    bool avx2 = __builtin_cpu_supports("avx2"),
         avx512 = avx2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq");
    if ((isa == 0 || isa >= 16) && avx512) {
        pixels_fn = pixels_avx512;
        return "avx512";
    }
    if ((isa == 0 || isa >= 8) && avx2 && __builtin_cpu_supports("fma")) {
        pixels_fn = pixels_avx2;
        return "avx2";
    }
#else
    (void)isa;
#endif
    return "scalar";
}

void view_srgb_pixels(float *sum, const float *add, float inv, uint32_t *out, int n) {
    pixels_fn(sum, add, 0, inv, out, 0, n, 1);
}

void view_srgb_rect(float *sum, const float *add, size_t stride, float inv, uint32_t *out, size_t pitch, int n,
                    int rows) {
    pixels_fn(sum, add, stride, inv, out, pitch, n, rows);
}
