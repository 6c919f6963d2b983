#pragma once
// Watertight ray-triangle intersection (Woop, Benthin and Wald 2013, "Watertight Ray/Triangle
// Intersection"): the ray is made the +z axis by a permutation and a shear, so the three 2D edge
// functions of neighbouring triangles are computed from identical inputs and a ray through a
// shared edge or vertex hits at least one of them.
#include "accel/wide_bvh.h"
#include "kernels/ray.h"
#include "kernels/simd.h"

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
    // The ray's frame (sec. 3): the axes that become x, y and z, and the shear that makes the ray the +z axis.
    // Without branches: the axes come from a comparison mask through tables, and coordinates are read by index
    // from memory (glm's operator[] is a switch), since the choice follows the ray's direction, which no branch
    // predictor can guess. The tables are static (a local constexpr array was copied to the stack on every call)
    // and |dir| is three ANDs (glm::abs compiled to compare-and-blend), both a shorter set-up on every ray
    // (docs/results.md#traversal-kernels).
    struct Shear {
        int kx, ky, kz;
        float sx, sy, sz;

        [[gnu::always_inline]] static Shear of(const Ray& ray) {
            const Vec3 a(std::abs(ray.dir.x), std::abs(ray.dir.y), std::abs(ray.dir.z));
            // The largest |dir| axis, as a >= chain would choose it: bits x>=y, x>=z, y>=z to the axis
            static constexpr int kLargest[8] = {2, 2, 2, 0, 1, 2, 1, 0};
            Shear s;
            s.kz = kLargest[int(a.x >= a.y) | int(a.x >= a.z) << 1 | int(a.y >= a.z) << 2];
            static constexpr int kNext[3] = {1, 2, 0};
            s.kx = kNext[s.kz];
            s.ky = kNext[s.kx];
            const float* dir = &ray.dir.x;
            const int swap = (s.kx ^ s.ky) & -int(dir[s.kz] < 0.0f);  // a negative z swaps x and y: keeps the winding
            s.kx ^= swap, s.ky ^= swap;
            s.sz = 1.0f / dir[s.kz];
            s.sx = dir[s.kx] * s.sz;
            s.sy = dir[s.ky] * s.sz;
            return s;
        }
    };

    [[gnu::always_inline]] explicit WatertightRay(const Ray& ray) : org_(ray.org), shear_(Shear::of(ray)) {
        const float* org = &org_.x;
        const auto [kx, ky, kz, sx, sy, sz] = shear_;
        using simd::broadcast;
        lanes_ = {{broadcast(org[kx]), broadcast(org[ky]), broadcast(org[kz])}, broadcast(sx), broadcast(sy), broadcast(sz)};
    }

    const Shear& shear() const { return shear_; }
    const Vec3& origin() const { return org_; }

    // Intersects in (tmin, hit.t]; on a hit updates `hit` and returns true.
    bool intersect(const Vec3& p0, const Vec3& p1, const Vec3& p2, uint32_t prim, float tmin, Hit& hit) const {
        const Vec3 a_vec = p0 - org_, b_vec = p1 - org_, c_vec = p2 - org_;
        const float *a = &a_vec.x, *b = &b_vec.x, *c = &c_vec.x;
        const auto [kx, ky, kz, sx, sy, sz] = shear_;
        // Sheared 2D coordinates (sec. 3, eq. 5), each one FMA: a shorter path to the edge functions than a product
        // and a difference, and one rounding, not two. A shared vertex still shears to the same point in every
        // triangle, which is all watertightness asks (docs/results.md#traversal-kernels).
        const float ax = std::fma(-sx, a[kz], a[kx]), ay = std::fma(-sy, a[kz], a[ky]);
        const float bx = std::fma(-sx, b[kz], b[kx]), by = std::fma(-sy, b[kz], b[ky]);
        const float cx = std::fma(-sx, c[kz], c[kx]), cy = std::fma(-sy, c[kz], c[ky]);
        // Edge functions (eq. 6). Exactly signed, so the paper's double-precision retry on zero is not needed.
        const float u = difference_of_products(cx, by, cy, bx);
        const float v = difference_of_products(ax, cy, ay, cx);
        const float w = difference_of_products(bx, ay, by, ax);
        if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
        const float det = u + v + w;
        if (det == 0.0f) return false;
        // t = sz (u a_z + v b_z + w c_z) / det (sec. 3, eq. 7, with the shear's z scale applied once, after the
        // interpolation); an overflow to inf (denormal directions, or det underflowing) is no hit.
        const float t = std::fma(u, a[kz], std::fma(v, b[kz], w * c[kz])) * (sz / det);
        if (!(t > tmin && t <= hit.t && t < std::numeric_limits<float>::infinity())) return false;
        hit = {t, v / det, w / det, prim};
        return true;
    }

#if defined(__FMA__)
    // W triangles at once, operation for operation the scalar test above, so every kernel finds the same hit
    // at the same distance. Returns the lane hit (the nearest), or -1.
    template <int W>
    [[gnu::always_inline]] int intersect_block(const TriangleBlock<W>& block, float tmin, Hit& hit) const {
        using S = simd::Simd<W>;
        using F = typename S::F;
        const F org[3] = {S::low(lanes_.org[0]), S::low(lanes_.org[1]), S::low(lanes_.org[2])};
        const F sx = S::low(lanes_.sx), sy = S::low(lanes_.sy), sz = S::low(lanes_.sz);
        F x[3], y[3], z[3];  // the vertices relative to the origin: x and y sheared, z unscaled (sz goes to t)
        for (int v = 0; v < 3; ++v) {
            const F px = S::sub(S::load(block.v[v][shear_.kx]), org[0]);
            const F py = S::sub(S::load(block.v[v][shear_.ky]), org[1]);
            const F pz = S::sub(S::load(block.v[v][shear_.kz]), org[2]);
            x[v] = S::fnmadd(sx, pz, px);
            y[v] = S::fnmadd(sy, pz, py);
            z[v] = pz;
        }
        const F u = difference_of_products_simd<S>(x[2], y[1], y[2], x[1]);
        const F v = difference_of_products_simd<S>(x[0], y[2], y[0], x[2]);
        const F w = difference_of_products_simd<S>(x[1], y[0], y[1], x[0]);
        const F zero = S::zero();
        // A negative and a positive edge function: the smallest is negative and the largest positive (where one
        // is NaN the lane may decide otherwise, but then det is NaN and the interval tests below fail).
        const F any_negative = S::lt(S::min(S::min(u, v), w), zero);
        const F any_positive = S::gt(S::max(S::max(u, v), w), zero);
        const F det = S::add(S::add(u, v), w);
        const F t = S::mul(S::fmadd(u, z[0], S::fmadd(v, z[1], S::mul(w, z[2]))), S::div(sz, det));
        const F t_min = S::set1(tmin), t_max = S::set1(hit.t);
        F valid = S::and_not(S::bit_and(any_negative, any_positive), S::neq(det, zero));
        valid = S::bit_and(valid, S::bit_and(S::gt(t, t_min), S::le(t, t_max)));
        valid = S::bit_and(valid, S::lt(t, S::set1(std::numeric_limits<float>::infinity())));
        return simd::record_nearest<S>(S::mask(valid), t, v, w, block.prim, hit, &det);
    }
#endif

private:
#if defined(__FMA__)
    template <class S>
    static typename S::F difference_of_products_simd(typename S::F a, typename S::F b, typename S::F c, typename S::F d) {
        const typename S::F cd = S::mul(c, d);
        const typename S::F error = S::fnmadd(c, d, cd);
        return S::add(S::fmsub(a, b, cd), error);
    }
#endif

    struct {
        simd::Broadcast org[3], sx, sy, sz;
    } lanes_;  // broadcast once per ray, not per block: a block test is the hot path of every leaf visit
    Vec3 org_;
    Shear shear_;
};

}  // namespace canopy
