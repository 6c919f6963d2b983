#pragma once
// Möller–Trumbore ray-triangle intersection (Möller and Trumbore 1997, "Fast, Minimum Storage Ray/Triangle
// Intersection"): the fast mode. Cheaper than the watertight test, but not watertight: a ray through a
// shared edge can slip between the two triangles.
#include "accel/wide_bvh.h"
#include "kernels/ray.h"
#include "kernels/simd.h"

#include <immintrin.h>

#include <bit>
#include <cmath>

namespace canopy {

class MollerTrumboreRay {
public:
    [[gnu::always_inline]] explicit MollerTrumboreRay(const Ray& ray) : org_(ray.org), dir_(ray.dir) {
        for (int a = 0; a < 3; ++a) org_lanes_[a] = simd::broadcast(org_[a]), dir_lanes_[a] = simd::broadcast(dir_[a]);
    }

    bool intersect(const Vec3& p0, const Vec3& p1, const Vec3& p2, uint32_t prim, float tmin, Hit& hit) const {
        const Vec3 e1 = p1 - p0, e2 = p2 - p0;
        const Vec3 p = glm::cross(dir_, e2);
        const float det = glm::dot(e1, p);
        if (det == 0.0f) return false;  // ray parallel to the plane
        const float inv_det = 1.0f / det;
        const Vec3 s = org_ - p0;
        const float u = glm::dot(s, p) * inv_det;
        if (!(u >= 0.0f && u <= 1.0f)) return false;
        const Vec3 q = glm::cross(s, e1);
        const float v = glm::dot(dir_, q) * inv_det;
        if (!(v >= 0.0f && u + v <= 1.0f)) return false;
        const float t = glm::dot(e2, q) * inv_det;
        if (!(t > tmin && t <= hit.t && t < std::numeric_limits<float>::infinity())) return false;
        hit = {t, u, v, prim};
        return true;
    }

#if defined(__FMA__)
    // W triangles at once, operation for operation the scalar test above; returns the lane hit (the nearest),
    // or -1.
    template <int W>
    [[gnu::always_inline]] int intersect_block(const TriangleBlock<W>& block, float tmin, Hit& hit) const {
        using S = simd::Simd<W>;
        using F = typename S::F;
        F e1[3], e2[3], s[3];
        const F dir[3] = {S::low(dir_lanes_[0]), S::low(dir_lanes_[1]), S::low(dir_lanes_[2])};
        for (int a = 0; a < 3; ++a) {
            const F p0 = S::load(block.v[0][a]);
            e1[a] = S::sub(S::load(block.v[1][a]), p0);
            e2[a] = S::sub(S::load(block.v[2][a]), p0);
            s[a] = S::sub(S::low(org_lanes_[a]), p0);
        }
        F p[3], q[3];
        cross<S>(dir, e2, p);
        cross<S>(s, e1, q);
        const F det = dot<S>(e1, p);
        const F inv_det = S::div(S::set1(1.0f), det);
        const F u = S::mul(dot<S>(s, p), inv_det);
        const F v = S::mul(dot<S>(dir, q), inv_det);
        const F t = S::mul(dot<S>(e2, q), inv_det);
        const F zero = S::zero();
        F valid = S::bit_and(S::neq(det, zero), S::ge(u, zero));
        valid = S::bit_and(valid, S::bit_and(S::ge(v, zero), S::le(S::add(u, v), S::set1(1.0f))));
        valid = S::bit_and(valid, S::bit_and(S::gt(t, S::set1(tmin)), S::le(t, S::set1(hit.t))));
        valid = S::bit_and(valid, S::lt(t, S::set1(std::numeric_limits<float>::infinity())));
        return simd::record_nearest<S>(S::mask(valid), t, u, v, block.prim, hit);
    }
#endif

private:
#if defined(__FMA__)
    // Rounded as glm::cross and glm::dot round, so the scalar and SIMD kernels find the same hits.
    template <class S>
    static void cross(const typename S::F a[3], const typename S::F b[3], typename S::F out[3]) {
        out[0] = S::sub(S::mul(a[1], b[2]), S::mul(a[2], b[1]));
        out[1] = S::sub(S::mul(a[2], b[0]), S::mul(a[0], b[2]));
        out[2] = S::sub(S::mul(a[0], b[1]), S::mul(a[1], b[0]));
    }
    template <class S>
    static typename S::F dot(const typename S::F a[3], const typename S::F b[3]) {
        return S::add(S::add(S::mul(a[0], b[0]), S::mul(a[1], b[1])), S::mul(a[2], b[2]));
    }
#endif
    Vec3 org_, dir_;
    simd::Broadcast org_lanes_[3], dir_lanes_[3];
};

}  // namespace canopy
