#pragma once
// Random numbers, cosine-weighted directions and robust ray offsets for the path tracer.
#include "base/geometry.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <utility>

namespace canopy {

inline uint64_t splitmix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

// PCG32 (O'Neill 2014), seeded per pixel and frame so every frame is reproducible on any thread count.
class Rng {
public:
    Rng(uint64_t pixel, uint64_t frame) : state_(splitmix64(pixel ^ splitmix64(frame))), inc_(splitmix64(frame) | 1u) {}

    uint32_t next_u32() {
        const uint64_t old = state_;
        state_ = old * 6364136223846793005ull + inc_;
        const uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
        const uint32_t rot = uint32_t(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
    }
    float next_float() { return float(next_u32() >> 8) * 0x1p-24f; }  // [0, 1)

private:
    uint64_t state_, inc_;
};

// cos and sin of 2 pi u for u in [0, 1): the nearest quarter turn q, exactly, and Taylor polynomials of the
// remaining angle in [-pi/4, pi/4] (float rounding's error, below 2e-7), rotated by q. libm's sincosf showed in a
// frame's profile (docs/results.md#traversal-kernels); a sampled direction needs no more than float accuracy, and
// none of sincosf's range reduction.
inline std::pair<float, float> turn_cos_sin(float u) {
    const float x = 4.0f * u, q = std::nearbyint(x);
    const float a = (x - q) * 1.57079632679489662f, a2 = a * a;
    const float sin_a = a * (1.0f + a2 * (-1.0f / 6.0f + a2 * (1.0f / 120.0f + a2 * (-1.0f / 5040.0f + a2 * (1.0f / 362880.0f)))));
    const float cos_a = 1.0f + a2 * (-0.5f + a2 * (1.0f / 24.0f + a2 * (-1.0f / 720.0f + a2 * (1.0f / 40320.0f))));
    const int quarter = int(q) & 3;  // (cos, sin) turned by quarter * 90 degrees
    const float c = quarter & 1 ? sin_a : cos_a, s = quarter & 1 ? cos_a : sin_a;
    return {(quarter + 1) & 2 ? -c : c, quarter & 2 ? -s : s};
}

// Cosine-weighted direction about unit normal n (Malley's method), with the orthonormal basis of
// Duff et al. 2017, "Building an Orthonormal Basis, Revisited". The result is unit length as it stands (weights
// whose squares sum to 1 on orthonormal t, s, n): normalising it again put a square root and a division on the way
// from each hit to the next ray (docs/results.md#shadings-second-normalisation).
inline Vec3 cosine_direction(const Vec3& n, float u1, float u2) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    const Vec3 t(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    const Vec3 s(b, sign + n.y * n.y * a, -n.y);
    const float r = std::sqrt(u1);
    const auto [cos_phi, sin_phi] = turn_cos_sin(u2);
    return r * cos_phi * t + r * sin_phi * s + std::sqrt(std::max(0.0f, 1.0f - u1)) * n;
}

// Moves a hit point off its surface along the normal n that faces the new ray: a few ulps scaled by
// the magnitude of each coordinate, a fixed epsilon near the origin (Wächter and Binder 2019,
// "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6).
inline Vec3 offset_ray_origin(const Vec3& p, const Vec3& n, float triangle_error = 0.0f) {
    constexpr float kOrigin = 1.0f / 32.0f, kFloatScale = 1.0f / 65536.0f, kIntScale = 256.0f;
    Vec3 out;
    for (int a = 0; a < 3; ++a) {
        const int32_t of = int32_t(kIntScale * n[a]);
        const int32_t bits = std::bit_cast<int32_t>(p[a]) + (p[a] < 0 ? -of : of);
        out[a] = std::abs(p[a]) < kOrigin ? p[a] + kFloatScale * n[a] : std::bit_cast<float>(bits);
    }
    return out + triangle_error * n;
}

// How far a hit point on a triangle may lie from the triangle's plane, seen by a ray-triangle test whose
// rounding scales with the vertex coordinates: gamma(7) times the largest of them (pbrt-v4 sec. 6.8.5's
// bound on the error of a point from barycentrics). The offset above is relative to the hit point alone;
// on a huge triangle whose vertices lie far from the hit point that is too little, and a ray leaving the
// surface re-hits it at a tiny t and continues on the wrong side.
inline float triangle_point_error(const Triangle& t) {
    const Vec3 m = glm::max(glm::abs(t.v0), glm::max(glm::abs(t.v1), glm::abs(t.v2)));
    return 7.0f * 0x1p-24f / (1.0f - 7.0f * 0x1p-24f) * std::max(m.x, std::max(m.y, m.z));
}

// How far a hit point computed as org + t dir may lie from the surface, for an intersector that reports the distance
// and the normal but not the triangle (Embree's hit record): the point's own rounding scales with its coordinates and
// the distance travelled, and the distance carries the intersector's rounding, a few ulps of the same magnitudes;
// 32 ulps of their sum covers both with a margin.
inline float ray_point_error(const Vec3& p, float t) {
    return 32.0f * 0x1p-24f * (std::max(std::abs(p.x), std::max(std::abs(p.y), std::abs(p.z))) + t);
}

}  // namespace canopy
