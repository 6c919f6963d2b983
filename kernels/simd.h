#pragma once
// Thin SIMD float vectors for the wide kernels: Simd<4> on SSE, Simd<8> on AVX. max/min keep their second
// operand where the first is NaN (the x86 semantics), which the slab test relies on: pass the running value
// second and a NaN from 0 * inf never replaces it, exactly as in the scalar test.
#include <immintrin.h>

#include <cstdint>

namespace canopy::simd {

template <int W>
struct Simd;

template <>
struct Simd<4> {
    using F = __m128;
    static F load(const float* p) { return _mm_load_ps(p); }
    static F set1(float x) { return _mm_set1_ps(x); }
    static F sub(F a, F b) { return _mm_sub_ps(a, b); }
    static F mul(F a, F b) { return _mm_mul_ps(a, b); }
    static F fmsub(F a, F b, F c) { return _mm_fmsub_ps(a, b, c); }
    static F max(F a, F b) { return _mm_max_ps(a, b); }
    static F min(F a, F b) { return _mm_min_ps(a, b); }
    static uint32_t le_mask(F a, F b) { return uint32_t(_mm_movemask_ps(_mm_cmple_ps(a, b))); }
    static void store(float* p, F a) { _mm_storeu_ps(p, a); }
};

#if defined(__AVX2__)
template <>
struct Simd<8> {
    using F = __m256;
    static F load(const float* p) { return _mm256_load_ps(p); }
    static F set1(float x) { return _mm256_set1_ps(x); }
    static F sub(F a, F b) { return _mm256_sub_ps(a, b); }
    static F mul(F a, F b) { return _mm256_mul_ps(a, b); }
    static F fmsub(F a, F b, F c) { return _mm256_fmsub_ps(a, b, c); }
    static F max(F a, F b) { return _mm256_max_ps(a, b); }
    static F min(F a, F b) { return _mm256_min_ps(a, b); }
    static uint32_t le_mask(F a, F b) { return uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ))); }
    static void store(float* p, F a) { _mm256_storeu_ps(p, a); }
};
#endif

}  // namespace canopy::simd
