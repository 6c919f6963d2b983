#pragma once
// The watertight test (watertight.h) of a leaf's triangles against a packet of rays, a ray a lane, one triangle
// at a time: on diffuse rays a packet reaches a leaf with more rays than the leaf's 8-lane blocks hold triangles
// (docs/results.md#tracers-single-and-stream). Each lane permutes and shears by its own
// ray's axes, so its arithmetic is, operation for operation, its ray's WatertightRay::intersect_block lane: the
// same hit at the same distance, ties going to the later triangle as there.
#include "kernels/packet_lanes.h"
#include "kernels/watertight.h"

namespace canopy::detail {

#if defined(__AVX2__) && defined(__FMA__)
class WatertightPacket {
    using L = PacketLanes;
    using F = L::F;
    using M = L::M;

public:
    // Per lane, the nearest hit so far: t (at first the ray's far limit), the edge functions v and w and their sum
    // det (barycentrics v / det and w / det, divided once at the end, as the block test divides its nearest lane's),
    // and the triangle's id as float bits.
    struct Nearest {
        F t, v, w, det, prim;
    };

    // From the packet's rays' own tests, lane by lane.
    WatertightPacket(const WatertightRay* rays, uint32_t count) {
        alignas(sizeof(F)) float lanes[6][L::kRays] = {};
        int axes[3][L::kRays] = {};
        const WatertightRay::Shear& first = rays[0].shear();
        axis_[0] = first.kx, axis_[1] = first.ky, axis_[2] = first.kz;
        uniform_ = true;
        for (uint32_t r = 0; r < count; ++r) {
            const WatertightRay::Shear& shear = rays[r].shear();
            const int k[3] = {shear.kx, shear.ky, shear.kz};
            for (int a = 0; a < 3; ++a) {
                lanes[a][r] = rays[r].origin()[k[a]];
                axes[a][r] = k[a];
                uniform_ &= k[a] == axis_[a];
            }
            lanes[3][r] = shear.sx, lanes[4][r] = shear.sy, lanes[5][r] = shear.sz;
        }
        for (int a = 0; a < 3; ++a) {
            org_[a] = L::load(lanes[a]);
            uint32_t is_0 = 0, is_1 = 0;
            for (uint32_t r = 0; r < count; ++r) is_0 |= uint32_t(axes[a][r] == 0) << r, is_1 |= uint32_t(axes[a][r] == 1) << r;
            is_0_[a] = L::from_bits(is_0), is_1_[a] = L::from_bits(is_1);
        }
        sx_ = L::load(lanes[3]), sy_ = L::load(lanes[4]), sz_ = L::load(lanes[5]);
    }

    // Every triangle of `block` against the rays of `active`; returns the lanes whose nearest hit it replaced.
    template <int W>
    [[gnu::always_inline]] M intersect_block(const TriangleBlock<W>& block, M active, F tmin, Nearest& nearest) const {
        M took = L::from_bits(0);
        for (int j = 0; j < W; ++j) {
            if (block.prim[j] == TriangleBlock<W>::kNone) continue;
            const Candidate c = uniform_ ? intersect<true>(block, j, active, tmin, nearest.t)
                                         : intersect<false>(block, j, active, tmin, nearest.t);
            const M hit = c.hit;
            nearest.t = L::select(hit, c.t, nearest.t);
            nearest.v = L::select(hit, c.v, nearest.v);
            nearest.w = L::select(hit, c.w, nearest.w);
            nearest.det = L::select(hit, c.det, nearest.det);
            nearest.prim = L::select(hit, L::broadcast(reinterpret_cast<const float*>(&block.prim[j])), nearest.prim);
            took = L::mask_or(took, hit);
        }
        return took;
    }

private:
    struct Candidate {
        M hit;
        F t, v, w, det;
    };

    // Triangle j of `block` against every lane: the lanes it hits within (tmin, tmax], its distances and edge
    // functions.
    template <bool Uniform, int W>
    [[gnu::always_inline]] Candidate intersect(const TriangleBlock<W>& block, int j, M active, F tmin, F tmax) const {
        F x[3], y[3], z[3];
        for (int v = 0; v < 3; ++v) {
            const F px = L::sub(component<Uniform>(block, v, 0, j), org_[0]);
            const F py = L::sub(component<Uniform>(block, v, 1, j), org_[1]);
            const F pz = L::sub(component<Uniform>(block, v, 2, j), org_[2]);
            x[v] = L::fnmadd(sx_, pz, px);
            y[v] = L::fnmadd(sy_, pz, py);
            z[v] = pz;
        }
        const F u = difference_of_products(x[2], y[1], y[2], x[1]);
        const F v = difference_of_products(x[0], y[2], y[0], x[2]);
        const F w = difference_of_products(x[1], y[0], y[1], x[0]);
        const F zero = L::zero();
        const M any_negative = L::lt(L::min(L::min(u, v), w), zero);
        const M any_positive = L::gt(L::max(L::max(u, v), w), zero);
        const F det = L::add(L::add(u, v), w);
        const F t = L::mul(L::fmadd(u, z[0], L::fmadd(v, z[1], L::mul(w, z[2]))), L::div(sz_, det));
        const float infinity = std::numeric_limits<float>::infinity();
        M valid = L::mask_and_not(L::mask_and(any_negative, any_positive), L::mask_and(active, L::neq(det, zero)));
        valid = L::mask_and(valid, L::mask_and(L::gt(t, tmin), L::le(t, tmax)));
        valid = L::mask_and(valid, L::lt(t, L::broadcast(&infinity)));
        return {valid, t, v, w, det};
    }

    // Vertex v's coordinate on permuted axis k (x, y or z of the ray's frame), per lane.
    template <bool Uniform, int W>
    [[gnu::always_inline]] F component(const TriangleBlock<W>& block, int v, int k, int j) const {
        if constexpr (Uniform) {
            return L::broadcast(&block.v[v][axis_[k]][j]);
        } else {
            const F c0 = L::broadcast(&block.v[v][0][j]), c1 = L::broadcast(&block.v[v][1][j]),
                    c2 = L::broadcast(&block.v[v][2][j]);
            return L::select(is_0_[k], c0, L::select(is_1_[k], c1, c2));
        }
    }

    static F difference_of_products(F a, F b, F c, F d) {
        const F cd = L::mul(c, d);
        const F error = L::fnmadd(c, d, cd);
        return L::add(L::fmsub(a, b, cd), error);
    }

    F org_[3];  // per lane, the origin on the ray's permuted axes
    F sx_, sy_, sz_;
    M is_0_[3], is_1_[3];  // per permuted axis: the lanes where it is world axis 0, and 1 (else 2)
    int axis_[3];          // the permuted axes when every lane has the same (uniform_)
    bool uniform_;
};
#endif

}  // namespace canopy::detail
