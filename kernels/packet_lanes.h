#pragma once
// The lanes of a ray packet (traverse_packet.h): 16 rays in AVX-512 registers where the CPU has them, else 8 in AVX2
// ones, with a lane mask type M (a mask register, or a vector of all-ones lanes) for selections.
#include "kernels/simd.h"

#include <immintrin.h>

#include <cstdint>

namespace canopy::detail {

#if defined(__AVX2__) && defined(__FMA__)
struct PacketLanes {
#if defined(__AVX512F__)
    static constexpr int kRays = 16;
    using F = __m512;
    using M = __mmask16;
    static F load(const float* p) { return _mm512_load_ps(p); }
    static F broadcast(const float* p) { return _mm512_set1_ps(*p); }
    static void store(float* p, F a) { _mm512_store_ps(p, a); }
    static F zero() { return _mm512_setzero_ps(); }
    static F set1(float x) { return _mm512_set1_ps(x); }
    static F bit_or(F a, F b) { return _mm512_or_ps(a, b); }
    static F bit_and(F a, F b) { return _mm512_and_ps(a, b); }
    static F bit_xor(F a, F b) { return _mm512_xor_ps(a, b); }
    static F and_not(F a, F b) { return _mm512_andnot_ps(a, b); }
    static F add(F a, F b) { return _mm512_add_ps(a, b); }
    static F sub(F a, F b) { return _mm512_sub_ps(a, b); }
    static F mul(F a, F b) { return _mm512_mul_ps(a, b); }
    static F div(F a, F b) { return _mm512_div_ps(a, b); }
    static F fmadd(F a, F b, F c) { return _mm512_fmadd_ps(a, b, c); }
    static F fmsub(F a, F b, F c) { return _mm512_fmsub_ps(a, b, c); }
    static F fnmadd(F a, F b, F c) { return _mm512_fnmadd_ps(a, b, c); }
    // Zero-masked forms with a full mask: the unmasked intrinsics make GCC 12 warn of an undefined operand inside them.
    static F min(F a, F b) { return _mm512_maskz_min_ps(0xffff, a, b); }
    static F max(F a, F b) { return _mm512_maskz_max_ps(0xffff, a, b); }
    static F max_bits(F a, F b) { return _mm512_castsi512_ps(_mm512_maskz_max_epi32(0xffff, _mm512_castps_si512(a), _mm512_castps_si512(b))); }
    static F min_bits(F a, F b) { return _mm512_castsi512_ps(_mm512_maskz_min_epi32(0xffff, _mm512_castps_si512(a), _mm512_castps_si512(b))); }
    static uint32_t le_mask_bits(F a, F b) { return _mm512_cmple_epi32_mask(_mm512_castps_si512(a), _mm512_castps_si512(b)); }
    static uint32_t le_mask(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_LE_OQ); }
    static M lt(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_LT_OQ); }
    static M le(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_LE_OQ); }
    static M gt(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_GT_OQ); }
    static M neq(F a, F b) { return _mm512_cmp_ps_mask(a, b, _CMP_NEQ_UQ); }
    static M mask_and(M a, M b) { return a & b; }
    static M mask_or(M a, M b) { return a | b; }
    static M mask_and_not(M a, M b) { return M(~a & b); }  // b and not a
    static M from_bits(uint32_t bits) { return M(bits); }
    static uint32_t bits(M m) { return m; }
    static F select(M m, F if_true, F if_false) { return _mm512_mask_blend_ps(m, if_false, if_true); }
#else
    static constexpr int kRays = 8;
    using S = simd::Simd<8>;
    using F = __m256;
    using M = __m256;
    static F load(const float* p) { return _mm256_load_ps(p); }
    static F broadcast(const float* p) { return _mm256_broadcast_ss(p); }
    static void store(float* p, F a) { _mm256_store_ps(p, a); }
    static F zero() { return S::zero(); }
    static F set1(float x) { return S::set1(x); }
    static F bit_or(F a, F b) { return S::bit_or(a, b); }
    static F bit_and(F a, F b) { return S::bit_and(a, b); }
    static F bit_xor(F a, F b) { return S::bit_xor(a, b); }
    static F and_not(F a, F b) { return S::and_not(a, b); }
    static F add(F a, F b) { return S::add(a, b); }
    static F sub(F a, F b) { return S::sub(a, b); }
    static F mul(F a, F b) { return S::mul(a, b); }
    static F div(F a, F b) { return S::div(a, b); }
    static F fmadd(F a, F b, F c) { return S::fmadd(a, b, c); }
    static F fmsub(F a, F b, F c) { return S::fmsub(a, b, c); }
    static F fnmadd(F a, F b, F c) { return S::fnmadd(a, b, c); }
    static F min(F a, F b) { return S::min(a, b); }
    static F max(F a, F b) { return S::max(a, b); }
    static F max_bits(F a, F b) { return S::max_bits(a, b); }
    static F min_bits(F a, F b) { return S::min_bits(a, b); }
    static uint32_t le_mask_bits(F a, F b) { return S::le_mask_bits(a, b); }
    static uint32_t le_mask(F a, F b) { return S::le_mask(a, b); }
    static M lt(F a, F b) { return S::lt(a, b); }
    static M le(F a, F b) { return S::le(a, b); }
    static M gt(F a, F b) { return S::gt(a, b); }
    static M neq(F a, F b) { return S::neq(a, b); }
    static M mask_and(M a, M b) { return S::bit_and(a, b); }
    static M mask_or(M a, M b) { return S::bit_or(a, b); }
    static M mask_and_not(M a, M b) { return S::and_not(a, b); }
    static M from_bits(uint32_t bits) {
        const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        const __m256i set = _mm256_and_si256(_mm256_set1_epi32(int(bits)), lane_bit);
        return _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bit));
    }
    static uint32_t bits(M m) { return S::mask(m); }
    static F select(M m, F if_true, F if_false) { return _mm256_blendv_ps(if_false, if_true, m); }
#endif
};
#endif

}  // namespace canopy::detail
