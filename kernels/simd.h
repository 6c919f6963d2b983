#pragma once
// Thin SIMD float vectors for the wide kernels: Simd<4> on SSE, Simd<8> on AVX. max/min keep their second
// operand where the first is NaN (the x86 semantics). Comparisons are ordered (false on NaN) except cmpneq, which
// is true on NaN as in IEEE 754. max_bits, min_bits and le_mask_bits compare floats by their bits as signed
// integers, which the slab test uses (see intersect_children in traverse.h).
#include <immintrin.h>

#include "kernels/ray.h"

#include <bit>
#include <cstdint>

namespace canopy::simd {

template <int W>
struct Simd;

// A per-ray value broadcast once to the widest vector this build has; a W-lane test reads its low W lanes
// (Simd<W>::low), so a ray set up once serves every block width.
#if defined(__AVX2__)
using Broadcast = __m256;
inline Broadcast broadcast(float x) { return _mm256_set1_ps(x); }
#else
using Broadcast = __m128;
inline Broadcast broadcast(float x) { return _mm_set1_ps(x); }
#endif

template <>
struct Simd<4> {
    using F = __m128;
    static F load(const float* p) { return _mm_load_ps(p); }
    static F set1(float x) { return _mm_set1_ps(x); }
#if defined(__AVX2__)
    static F low(Broadcast b) { return _mm256_castps256_ps128(b); }
#else
    static F low(Broadcast b) { return b; }
#endif
    static F zero() { return _mm_setzero_ps(); }
    static F add(F a, F b) { return _mm_add_ps(a, b); }
    static F sub(F a, F b) { return _mm_sub_ps(a, b); }
    static F mul(F a, F b) { return _mm_mul_ps(a, b); }
    static F div(F a, F b) { return _mm_div_ps(a, b); }
    static F fmadd(F a, F b, F c) { return _mm_fmadd_ps(a, b, c); }
    static F fmsub(F a, F b, F c) { return _mm_fmsub_ps(a, b, c); }
    static F fnmadd(F a, F b, F c) { return _mm_fnmadd_ps(a, b, c); }
    static F max(F a, F b) { return _mm_max_ps(a, b); }
    static F min(F a, F b) { return _mm_min_ps(a, b); }
    static F bit_and(F a, F b) { return _mm_and_ps(a, b); }
    static F bit_or(F a, F b) { return _mm_or_ps(a, b); }
    static F bit_xor(F a, F b) { return _mm_xor_ps(a, b); }
    static F and_not(F a, F b) { return _mm_andnot_ps(a, b); }  // ~a & b
    static F lt(F a, F b) { return _mm_cmplt_ps(a, b); }
    static F le(F a, F b) { return _mm_cmple_ps(a, b); }
    static F gt(F a, F b) { return _mm_cmpgt_ps(a, b); }
    static F ge(F a, F b) { return _mm_cmpge_ps(a, b); }
    static F neq(F a, F b) { return _mm_cmpneq_ps(a, b); }
    static uint32_t mask(F a) { return uint32_t(_mm_movemask_ps(a)); }
    static uint32_t le_mask(F a, F b) { return mask(le(a, b)); }
    static __m128i bits(F a) { return _mm_castps_si128(a); }
    static F max_bits(F a, F b) { return _mm_castsi128_ps(_mm_max_epi32(bits(a), bits(b))); }
    static F min_bits(F a, F b) { return _mm_castsi128_ps(_mm_min_epi32(bits(a), bits(b))); }
    static uint32_t le_mask_bits(F a, F b) { return ~mask(_mm_castsi128_ps(_mm_cmpgt_epi32(bits(a), bits(b)))) & 0xfu; }
    static void store(float* p, F a) { _mm_storeu_ps(p, a); }
};

#if defined(__AVX2__)
template <>
struct Simd<8> {
    using F = __m256;
    static F load(const float* p) { return _mm256_load_ps(p); }
    static F load_bytes(const uint8_t* p) {  // 8 bytes as floats 0 to 255
        return _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
    }
    static F set1(float x) { return _mm256_set1_ps(x); }
    static F low(Broadcast b) { return b; }
    static F zero() { return _mm256_setzero_ps(); }
    static F add(F a, F b) { return _mm256_add_ps(a, b); }
    static F sub(F a, F b) { return _mm256_sub_ps(a, b); }
    static F mul(F a, F b) { return _mm256_mul_ps(a, b); }
    static F div(F a, F b) { return _mm256_div_ps(a, b); }
    static F fmadd(F a, F b, F c) { return _mm256_fmadd_ps(a, b, c); }
    static F fmsub(F a, F b, F c) { return _mm256_fmsub_ps(a, b, c); }
    static F fnmadd(F a, F b, F c) { return _mm256_fnmadd_ps(a, b, c); }
    static F max(F a, F b) { return _mm256_max_ps(a, b); }
    static F min(F a, F b) { return _mm256_min_ps(a, b); }
    static F bit_and(F a, F b) { return _mm256_and_ps(a, b); }
    static F bit_or(F a, F b) { return _mm256_or_ps(a, b); }
    static F bit_xor(F a, F b) { return _mm256_xor_ps(a, b); }
    static F and_not(F a, F b) { return _mm256_andnot_ps(a, b); }
    static F lt(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
    static F le(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
    static F gt(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
    static F ge(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
    static F neq(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
    static uint32_t mask(F a) { return uint32_t(_mm256_movemask_ps(a)); }
    static uint32_t le_mask(F a, F b) { return mask(le(a, b)); }
    static __m256i bits(F a) { return _mm256_castps_si256(a); }
    static F max_bits(F a, F b) { return _mm256_castsi256_ps(_mm256_max_epi32(bits(a), bits(b))); }
    static F min_bits(F a, F b) { return _mm256_castsi256_ps(_mm256_min_epi32(bits(a), bits(b))); }
    // With AVX-512 the comparison writes a mask register, read in one move, where AVX2 needs a movemask and a NOT:
    // two instructions off every node's critical path, which made bvh8 frames faster and left bvh4's within noise,
    // so Simd<4> keeps AVX2's (docs/results.md#traversal-kernels). The triangle tests' comparisons stay vectors: as
    // mask registers GCC chains them into masked comparisons, one after another, which measured slower.
    static uint32_t le_mask_bits(F a, F b) {
#if defined(__AVX512VL__)
        return _mm256_cmple_epi32_mask(bits(a), bits(b));
#else
        return ~mask(_mm256_castsi256_ps(_mm256_cmpgt_epi32(bits(a), bits(b)))) & 0xffu;
#endif
    }
    static void store(float* p, F a) { _mm256_storeu_ps(p, a); }
};
#endif

// Records in `hit` the nearest of the lanes in `lanes` (a bit mask of valid hits) and returns its lane, or -1
// when there are none. Its barycentrics are u and v, or u / den and v / den when `den` is given, divided for that
// lane only (the calls are inlined with `den` a constant, so a test without it pays for no division). Ties go to
// the later lane, as the scalar kernel's loop over a leaf's triangles does.
template <class S>
[[gnu::always_inline]] inline int record_nearest(uint32_t lanes, typename S::F t, typename S::F u, typename S::F v,
                                                  const uint32_t* prim, Hit& hit, const typename S::F* den = nullptr) {
    if (!lanes) return -1;
    constexpr int W = sizeof(typename S::F) / sizeof(float);
    alignas(32) float ts[W], us[W], vs[W], dens[W];
    S::store(ts, t);
    S::store(us, u);
    S::store(vs, v);
    int best = std::countr_zero(lanes);
    for (lanes &= lanes - 1; lanes; lanes &= lanes - 1) {
        const int lane = std::countr_zero(lanes);
        if (ts[lane] <= ts[best]) best = lane;
    }
    hit = {ts[best], us[best], vs[best], prim[best]};
    if (den) {
        S::store(dens, *den);
        hit.u /= dens[best], hit.v /= dens[best];
    }
    return best;
}

}  // namespace canopy::simd
