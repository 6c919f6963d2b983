#pragma once
// Watertight ray-triangle intersection (Woop, Benthin and Wald 2013, "Watertight Ray/Triangle
// Intersection"): the ray is made the +z axis by a permutation and a shear, so the three 2D edge
// functions of neighbouring triangles are computed from identical inputs and a ray through a
// shared edge or vertex hits at least one of them.
#include "kernels/ray.h"

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

private:
    Vec3 org_;
    int kx_, ky_, kz_;
    float sx_, sy_, sz_;
};

}  // namespace canopy
