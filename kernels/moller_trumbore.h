#pragma once
// Möller–Trumbore ray-triangle intersection (Möller and Trumbore 1997, "Fast, Minimum Storage Ray/Triangle
// Intersection"): the fast mode. Cheaper than the watertight test, but not watertight: a ray through a
// shared edge can slip between the two triangles.
#include "accel/wide_bvh.h"
#include "kernels/ray.h"

#include <immintrin.h>

#include <bit>
#include <cmath>

namespace canopy {

class MollerTrumboreRay {
public:
    explicit MollerTrumboreRay(const Ray& ray) : org_(ray.org), dir_(ray.dir) {
#if defined(__FMA__)
        for (int a = 0; a < 3; ++a) org4_[a] = _mm_set1_ps(org_[a]), dir4_[a] = _mm_set1_ps(dir_[a]);
#endif
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
    // Four triangles at once; returns the lane hit (the nearest), or -1.
    int intersect4(const TriangleBlock4& block, float tmin, Hit& hit) const {
        __m128 e1[3], e2[3], s[3];
        for (int a = 0; a < 3; ++a) {
            const __m128 p0 = _mm_load_ps(block.v[0][a]);
            e1[a] = _mm_sub_ps(_mm_load_ps(block.v[1][a]), p0);
            e2[a] = _mm_sub_ps(_mm_load_ps(block.v[2][a]), p0);
            s[a] = _mm_sub_ps(org4_[a], p0);
        }
        __m128 p[3], q[3];
        cross(dir4_, e2, p);
        cross(s, e1, q);
        const __m128 det = dot(e1, p);
        const __m128 inv_det = _mm_div_ps(_mm_set1_ps(1.0f), det);
        const __m128 u = _mm_mul_ps(dot(s, p), inv_det);
        const __m128 v = _mm_mul_ps(dot(dir4_, q), inv_det);
        const __m128 t = _mm_mul_ps(dot(e2, q), inv_det);
        const __m128 zero = _mm_setzero_ps();
        __m128 valid = _mm_and_ps(_mm_cmpneq_ps(det, zero), _mm_cmpge_ps(u, zero));
        valid = _mm_and_ps(valid, _mm_and_ps(_mm_cmpge_ps(v, zero), _mm_cmple_ps(_mm_add_ps(u, v), _mm_set1_ps(1.0f))));
        valid = _mm_and_ps(valid, _mm_and_ps(_mm_cmpgt_ps(t, _mm_set1_ps(tmin)), _mm_cmple_ps(t, _mm_set1_ps(hit.t))));
        valid = _mm_and_ps(valid, _mm_cmplt_ps(t, _mm_set1_ps(std::numeric_limits<float>::infinity())));
        int mask = _mm_movemask_ps(valid);
        if (!mask) return -1;
        alignas(16) float ts[4], us[4], vs[4];
        _mm_store_ps(ts, t);
        _mm_store_ps(us, u);
        _mm_store_ps(vs, v);
        int best = std::countr_zero(unsigned(mask));
        for (mask &= mask - 1; mask; mask &= mask - 1) {
            const int lane = std::countr_zero(unsigned(mask));
            if (ts[lane] <= ts[best]) best = lane;
        }
        hit = {ts[best], us[best], vs[best], block.prim[best]};
        return best;
    }
#endif

private:
#if defined(__FMA__)
    // Rounded as glm::cross and glm::dot round, so the scalar and SIMD kernels find the same hits.
    static void cross(const __m128 a[3], const __m128 b[3], __m128 out[3]) {
        out[0] = _mm_sub_ps(_mm_mul_ps(a[1], b[2]), _mm_mul_ps(a[2], b[1]));
        out[1] = _mm_sub_ps(_mm_mul_ps(a[2], b[0]), _mm_mul_ps(a[0], b[2]));
        out[2] = _mm_sub_ps(_mm_mul_ps(a[0], b[1]), _mm_mul_ps(a[1], b[0]));
    }
    static __m128 dot(const __m128 a[3], const __m128 b[3]) {
        return _mm_add_ps(_mm_add_ps(_mm_mul_ps(a[0], b[0]), _mm_mul_ps(a[1], b[1])), _mm_mul_ps(a[2], b[2]));
    }
    __m128 org4_[3], dir4_[3];
#endif
    Vec3 org_, dir_;
};

}  // namespace canopy
