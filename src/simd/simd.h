/* SIMD packet types of width 4, 8 and 16: GCC/Clang vector extensions for the arithmetic, thin
 * wrappers with intrinsics for what compilers do not pattern-match (min/max, movemask, blend, rcp),
 * and a portable fallback for every wrapper. The same source compiles for every ISA; which
 * instructions come out depends on the -m flags of the file that includes it. */
#ifndef RP_SIMD_H
#define RP_SIMD_H

#include <stdint.h>
#include <string.h>
#if defined(__SSE__)
#include <immintrin.h>
#endif

typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));
typedef float vf8 __attribute__((vector_size(32)));
typedef int32_t vi8 __attribute__((vector_size(32)));
typedef float vf16 __attribute__((vector_size(64)));
typedef int32_t vi16 __attribute__((vector_size(64)));

/* Unaligned loads/stores of packets through 4-byte-aligned, may_alias vector types (the GCC/Clang
 * idiom for movups): memcpy into a vector sometimes came out as an integer load, a store to the
 * stack and a float reload. */
typedef float vf4u __attribute__((vector_size(16), aligned(4), may_alias));
typedef int32_t vi4u __attribute__((vector_size(16), aligned(4), may_alias));
typedef float vf8u __attribute__((vector_size(32), aligned(4), may_alias));
typedef int32_t vi8u __attribute__((vector_size(32), aligned(4), may_alias));
typedef float vf16u __attribute__((vector_size(64), aligned(4), may_alias));
typedef int32_t vi16u __attribute__((vector_size(64), aligned(4), may_alias));
#define SIMD_DEFINE_LOADS_(W)                                                                  \
    static inline vf##W vf##W##_load(const float *p) { return *(const vf##W##u *)p; }         \
    static inline vi##W vi##W##_load(const void *p) { return *(const vi##W##u *)p; }          \
    static inline void vf##W##_store(float *p, vf##W v) { *(vf##W##u *)p = v; }               \
    static inline void vi##W##_store(void *p, vi##W v) { *(vi##W##u *)p = v; }                \
    /* x - 0 rather than 0 + x: the same value for every x but -0 (kept), and GCC folds it, where \
     * 0 + x costs an add before every broadcast */                                             \
    static inline vf##W vf##W##_splat(float x) { return x - (vf##W){0}; }                    \
    static inline vi##W vi##W##_splat(int32_t x) { return (vi##W){0} + x; }                  \
    /* Lanes where m is all ones take a, others b. */                                          \
    static inline vf##W vf##W##_select(vi##W m, vf##W a, vf##W b) {                           \
        return (vf##W)(((vi##W)a & m) | ((vi##W)b & ~m));                                       \
    }                                                                                           \
    static inline vi##W vi##W##_select(vi##W m, vi##W a, vi##W b) { return (a & m) | (b & ~m); } \
    static inline vf##W vf##W##_abs(vf##W a) {                                                 \
        return (vf##W)((vi##W)a & vi##W##_splat(0x7fffffff));                                   \
    }                                                                                           \
    /* Flips the sign of a where s is negative (s's sign bit xor'ed into a). */                \
    static inline vf##W vf##W##_xorsign(vf##W a, vf##W s) {                                    \
        return (vf##W)((vi##W)a ^ ((vi##W)s & vi##W##_splat((int32_t)0x80000000u)));           \
    }
SIMD_DEFINE_LOADS_(4)
SIMD_DEFINE_LOADS_(8)
SIMD_DEFINE_LOADS_(16)
#undef SIMD_DEFINE_LOADS_

/* min / max: IEEE minps semantics (the second operand is returned when either is NaN). */
static inline vf4 vf4_min(vf4 a, vf4 b) {
#if defined(__SSE__)
    return (vf4)_mm_min_ps((__m128)a, (__m128)b);
#else
    return vf4_select(a < b, a, b);
#endif
}
static inline vf4 vf4_max(vf4 a, vf4 b) {
#if defined(__SSE__)
    return (vf4)_mm_max_ps((__m128)a, (__m128)b);
#else
    return vf4_select(a > b, a, b);
#endif
}
static inline vf8 vf8_min(vf8 a, vf8 b) {
#if defined(__AVX2__)
    return (vf8)_mm256_min_ps((__m256)a, (__m256)b);
#else
    return vf8_select(a < b, a, b);
#endif
}
static inline vf8 vf8_max(vf8 a, vf8 b) {
#if defined(__AVX2__)
    return (vf8)_mm256_max_ps((__m256)a, (__m256)b);
#else
    return vf8_select(a > b, a, b);
#endif
}
static inline vf16 vf16_min(vf16 a, vf16 b) {
#if defined(__AVX512F__)
    return (vf16)_mm512_min_ps((__m512)a, (__m512)b);
#else
    return vf16_select(a < b, a, b);
#endif
}
static inline vf16 vf16_max(vf16 a, vf16 b) {
#if defined(__AVX512F__)
    return (vf16)_mm512_max_ps((__m512)a, (__m512)b);
#else
    return vf16_select(a > b, a, b);
#endif
}

/* movemask: bit i set when lane i of a -1/0 mask is set. */
static inline uint32_t vi4_movemask(vi4 m) {
#if defined(__SSE4_2__)
    return (uint32_t)_mm_movemask_ps((__m128)m);
#else
    uint32_t r = 0;
    for (int i = 0; i < 4; i++) r |= (uint32_t)(m[i] < 0) << i;
    return r;
#endif
}
static inline uint32_t vi8_movemask(vi8 m) {
#if defined(__AVX2__)
    return (uint32_t)_mm256_movemask_ps((__m256)m);
#else
    uint32_t r = 0;
    for (int i = 0; i < 8; i++) r |= (uint32_t)(m[i] < 0) << i;
    return r;
#endif
}
static inline uint32_t vi16_movemask(vi16 m) {
#if defined(__AVX512DQ__)
    return (uint32_t)_mm512_movepi32_mask((__m512i)m);
#else
    uint32_t r = 0;
    for (int i = 0; i < 16; i++) r |= (uint32_t)(m[i] < 0) << i;
    return r;
#endif
}
/* movemask(a <= b) (false where either is NaN), straight from the compare's mask register where
 * the ISA has one: with AVX-512, GCC turned movemask(a <= b) into compare -> k, k -> -1/0 vector
 * (vmovdqa32), vector -> k (vpmovd2m), k -> bits, on the critical path of every box test. */
static inline uint32_t vf4_le_bits(vf4 a, vf4 b) { return vi4_movemask(a <= b); }
static inline uint32_t vf8_le_bits(vf8 a, vf8 b) { return vi8_movemask(a <= b); }
static inline uint32_t vf16_le_bits(vf16 a, vf16 b) {
#if defined(__AVX512F__)
    return (uint32_t)_mm512_cmp_ps_mask((__m512)a, (__m512)b, _CMP_LE_OS);
#else
    return vi16_movemask(a <= b);
#endif
}

/* Lane mask from a bit mask. */
static inline vi4 vi4_from_bits(uint32_t bits) {
    return ((vi4){1, 2, 4, 8} & vi4_splat((int32_t)bits)) != 0;
}
static inline vi8 vi8_from_bits(uint32_t bits) {
    return ((vi8){1, 2, 4, 8, 16, 32, 64, 128} & vi8_splat((int32_t)bits)) != 0;
}
static inline vi16 vi16_from_bits(uint32_t bits) {
    return ((vi16){1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768} &
            vi16_splat((int32_t)bits)) != 0;
}

/* Horizontal reductions. */
static inline float vf4_reduce_min(vf4 a) {
    float r = a[0];
    for (int i = 1; i < 4; i++) r = a[i] < r ? a[i] : r;
    return r;
}
static inline float vf8_reduce_min(vf8 a) {
    float r = a[0];
    for (int i = 1; i < 8; i++) r = a[i] < r ? a[i] : r;
    return r;
}
static inline float vf16_reduce_min(vf16 a) {
    float r = a[0];
    for (int i = 1; i < 16; i++) r = a[i] < r ? a[i] : r;
    return r;
}

/* Horizontal minimum for heuristics (traversal order): a tree of minps, whose handling of NaN
 * differs from vf*_reduce_min's; never for results. */
static inline float vf4_hmin_fast(vf4 a) {
#if defined(__SSE__)
    __m128 x = (__m128)a;
    x = _mm_min_ps(x, _mm_movehl_ps(x, x));
    x = _mm_min_ss(x, _mm_shuffle_ps(x, x, 1));
    return _mm_cvtss_f32(x);
#else
    return vf4_reduce_min(a);
#endif
}
static inline float vf8_hmin_fast(vf8 a) {
#if defined(__AVX__)
    __m128 x = _mm_min_ps(_mm256_castps256_ps128((__m256)a), _mm256_extractf128_ps((__m256)a, 1));
    return vf4_hmin_fast((vf4)x);
#else
    return vf8_reduce_min(a);
#endif
}
static inline float vf16_hmin_fast(vf16 a) {
#if defined(__AVX512F__)
    return _mm512_reduce_min_ps((__m512)a);
#else
    return vf16_reduce_min(a);
#endif
}

static inline float vf4_reduce_max(vf4 a) {
    float r = a[0];
    for (int i = 1; i < 4; i++) r = a[i] > r ? a[i] : r;
    return r;
}
static inline float vf8_reduce_max(vf8 a) {
    float r = a[0];
    for (int i = 1; i < 8; i++) r = a[i] > r ? a[i] : r;
    return r;
}
static inline float vf16_reduce_max(vf16 a) {
    float r = a[0];
    for (int i = 1; i < 16; i++) r = a[i] > r ? a[i] : r;
    return r;
}

/* Square roots (correctly rounded, as sqrtf). */
static inline vf4 vf4_sqrt(vf4 a) {
#if defined(__SSE__)
    return (vf4)_mm_sqrt_ps((__m128)a);
#else
    for (int i = 0; i < 4; i++) a[i] = __builtin_sqrtf(a[i]);
    return a;
#endif
}
static inline vf8 vf8_sqrt(vf8 a) {
#if defined(__AVX__)
    return (vf8)_mm256_sqrt_ps((__m256)a);
#else
    for (int i = 0; i < 8; i++) a[i] = __builtin_sqrtf(a[i]);
    return a;
#endif
}
static inline vf16 vf16_sqrt(vf16 a) {
#if defined(__AVX512F__)
    return (vf16)_mm512_sqrt_ps((__m512)a);
#else
    for (int i = 0; i < 16; i++) a[i] = __builtin_sqrtf(a[i]);
    return a;
#endif
}

/* Two 4-lane halves loaded into one 8-lane vector (lo in lanes 0-3). */
static inline vf8 vf8_load2(const float *lo, const float *hi) {
#if defined(__AVX__)
    return (vf8)_mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(lo)), _mm_loadu_ps(hi), 1);
#else
    vf8 r;
    memcpy(&r, lo, 16);
    memcpy((char *)&r + 16, hi, 16);
    return r;
#endif
}
static inline vi8 vi8_load2(const void *lo, const void *hi) {
#if defined(__AVX__)
    return (vi8)_mm256_insertf128_si256(_mm256_castsi128_si256(_mm_loadu_si128((const __m128i *)lo)),
                                        _mm_loadu_si128((const __m128i *)hi), 1);
#else
    vi8 r;
    memcpy(&r, lo, 16);
    memcpy((char *)&r + 16, hi, 16);
    return r;
#endif
}

static inline uint32_t simd_ctz(uint32_t x) { return (uint32_t)__builtin_ctz(x); }
static inline uint32_t simd_popcount(uint32_t x) { return (uint32_t)__builtin_popcount(x); }

#endif
