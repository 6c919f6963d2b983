#pragma once
// Watertight ray-triangle intersection (Woop, Benthin and Wald 2013, "Watertight Ray/Triangle
// Intersection"): the ray is made the +z axis by a permutation and a shear, so the three 2D edge
// functions of neighbouring triangles are computed from identical inputs and a ray through a
// shared edge or vertex hits at least one of them.
#include "accel/wide_bvh.h"
#include "kernels/ray.h"

#include <immintrin.h>

#include <bit>
#include <cmath>
#include <utility>

namespace canopy {

// a * b - c * d within 1.5 ulp (Kahan's algorithm with FMA; pbrt-v4's DifferenceOfProducts). Its sign is the
// exact sign, so edge functions of edge-on triangles, where the two products nearly cancel, keep their true
// signs: plain float products there can give three equal signs and a hit far outside the triangle.
inline float difference_of_products(float a, float b, float c, float d) {
    const float cd = c * d;
    const float error = std::fma(-c, d, cd);
    return std::fma(a, b, -cd) + error;
}

class WatertightRay {
public:
    explicit WatertightRay(const Ray& ray) : org_(ray.org) {
        const Vec3 a = glm::abs(ray.dir);
        kz_ = a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);  // sec. 3: largest |dir| axis
        kx_ = (kz_ + 1) % 3;
        ky_ = (kx_ + 1) % 3;
        if (ray.dir[kz_] < 0.0f) std::swap(kx_, ky_);  // keeps the triangle winding
        sz_ = 1.0f / ray.dir[kz_];
        sx_ = ray.dir[kx_] * sz_;
        sy_ = ray.dir[ky_] * sz_;
#if defined(__FMA__)
        org4_[0] = _mm_set1_ps(org_[kx_]), org4_[1] = _mm_set1_ps(org_[ky_]), org4_[2] = _mm_set1_ps(org_[kz_]);
        sx4_ = _mm_set1_ps(sx_), sy4_ = _mm_set1_ps(sy_), sz4_ = _mm_set1_ps(sz_);
#endif
    }

    // Intersects in (tmin, hit.t]; on a hit updates `hit` and returns true.
    bool intersect(const Vec3& p0, const Vec3& p1, const Vec3& p2, uint32_t prim, float tmin, Hit& hit) const {
        const Vec3 a = p0 - org_, b = p1 - org_, c = p2 - org_;
        // Sheared 2D coordinates (sec. 3, eq. 5)
        const float ax = a[kx_] - sx_ * a[kz_], ay = a[ky_] - sy_ * a[kz_];
        const float bx = b[kx_] - sx_ * b[kz_], by = b[ky_] - sy_ * b[kz_];
        const float cx = c[kx_] - sx_ * c[kz_], cy = c[ky_] - sy_ * c[kz_];
        // Edge functions (eq. 6). Exactly signed, so the paper's double-precision retry on zero is not needed.
        const float u = difference_of_products(cx, by, cy, bx);
        const float v = difference_of_products(ax, cy, ay, cx);
        const float w = difference_of_products(bx, ay, by, ax);
        if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
        const float det = u + v + w;
        if (det == 0.0f) return false;
        const float az = sz_ * a[kz_], bz = sz_ * b[kz_], cz = sz_ * c[kz_];
        const float t_scaled = u * az + v * bz + w * cz;
        // Compare t_scaled / det against the interval without dividing (sign of det folded in).
        const float sign = std::copysign(1.0f, det);
        const float abs_det = std::abs(det);
        const float ts = t_scaled * sign;
        if (ts <= tmin * abs_det || ts > hit.t * abs_det) return false;
        const float inv_det = 1.0f / det;
        const float t = t_scaled * inv_det;
        // Rounding of the division; an overflow to inf (denormal directions) is no hit.
        if (!(t > tmin && t <= hit.t && t < std::numeric_limits<float>::infinity())) return false;
        hit = {t, v * inv_det, w * inv_det, prim};
        return true;
    }

#if defined(__FMA__)
    // Four triangles at once, operation for operation the scalar test above, so every kernel finds the same
    // hit at the same distance. Returns the lane hit (the nearest), or -1.
    int intersect4(const TriangleBlock4& block, float tmin, Hit& hit) const {
        __m128 x[3], y[3], z[3];  // sheared coordinates of the three vertices
        for (int v = 0; v < 3; ++v) {
            const __m128 px = _mm_sub_ps(_mm_load_ps(block.v[v][kx_]), org4_[0]);
            const __m128 py = _mm_sub_ps(_mm_load_ps(block.v[v][ky_]), org4_[1]);
            const __m128 pz = _mm_sub_ps(_mm_load_ps(block.v[v][kz_]), org4_[2]);
            x[v] = _mm_sub_ps(px, _mm_mul_ps(sx4_, pz));
            y[v] = _mm_sub_ps(py, _mm_mul_ps(sy4_, pz));
            z[v] = _mm_mul_ps(sz4_, pz);
        }
        const __m128 u = difference_of_products4(x[2], y[1], y[2], x[1]);
        const __m128 v = difference_of_products4(x[0], y[2], y[0], x[2]);
        const __m128 w = difference_of_products4(x[1], y[0], y[1], x[0]);
        const __m128 zero = _mm_setzero_ps();
        const __m128 any_negative = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(u, zero), _mm_cmplt_ps(v, zero)), _mm_cmplt_ps(w, zero));
        const __m128 any_positive = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(u, zero), _mm_cmpgt_ps(v, zero)), _mm_cmpgt_ps(w, zero));
        const __m128 det = _mm_add_ps(_mm_add_ps(u, v), w);
        const __m128 t_scaled = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u, z[0]), _mm_mul_ps(v, z[1])), _mm_mul_ps(w, z[2]));
        const __m128 sign_bit = _mm_and_ps(det, _mm_set1_ps(-0.0f));
        const __m128 abs_det = _mm_andnot_ps(_mm_set1_ps(-0.0f), det);
        const __m128 ts = _mm_xor_ps(t_scaled, sign_bit);
        const __m128 inv_det = _mm_div_ps(_mm_set1_ps(1.0f), det);
        const __m128 t = _mm_mul_ps(t_scaled, inv_det);
        const __m128 t_min = _mm_set1_ps(tmin), t_max = _mm_set1_ps(hit.t);
        __m128 valid = _mm_andnot_ps(_mm_and_ps(any_negative, any_positive), _mm_cmpneq_ps(det, zero));
        valid = _mm_and_ps(valid, _mm_cmpgt_ps(ts, _mm_mul_ps(t_min, abs_det)));
        valid = _mm_and_ps(valid, _mm_cmple_ps(ts, _mm_mul_ps(t_max, abs_det)));
        valid = _mm_and_ps(valid, _mm_and_ps(_mm_cmpgt_ps(t, t_min), _mm_cmple_ps(t, t_max)));
        valid = _mm_and_ps(valid, _mm_cmplt_ps(t, _mm_set1_ps(std::numeric_limits<float>::infinity())));
        int mask = _mm_movemask_ps(valid);
        if (!mask) return -1;
        alignas(16) float ts_lane[4], us[4], vs[4];
        _mm_store_ps(ts_lane, t);
        _mm_store_ps(us, _mm_mul_ps(v, inv_det));
        _mm_store_ps(vs, _mm_mul_ps(w, inv_det));
        int best = std::countr_zero(unsigned(mask));
        for (mask &= mask - 1; mask; mask &= mask - 1) {
            const int lane = std::countr_zero(unsigned(mask));
            if (ts_lane[lane] <= ts_lane[best]) best = lane;  // ties go to the later triangle, as in the scalar loop
        }
        hit = {ts_lane[best], us[best], vs[best], block.prim[best]};
        return best;
    }
#endif

private:
#if defined(__FMA__)
    static __m128 difference_of_products4(__m128 a, __m128 b, __m128 c, __m128 d) {
        const __m128 cd = _mm_mul_ps(c, d);
        const __m128 error = _mm_fnmadd_ps(c, d, cd);
        return _mm_add_ps(_mm_fmsub_ps(a, b, cd), error);
    }
#endif

    Vec3 org_;
    int kx_, ky_, kz_;
    float sx_, sy_, sz_;
#if defined(__FMA__)
    __m128 org4_[3], sx4_, sy4_, sz4_;  // the same values broadcast once per ray for intersect4
#endif
};

}  // namespace canopy
