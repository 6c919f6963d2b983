#pragma once
// Front-to-back traversal of a KdTree (accel/kdtree.h), one ray at a time: the classic recursive tmin/tmax scheme
// made iterative with a stack (Jansen 1986; the "TA_rec^B" family of Havran's thesis, appendix C), leaves tested
// with WatertightRay (default) or MollerTrumboreRay a block of kKdLanes triangles at once, as the wide BVH kernels
// test theirs (intersect_leaf in kernels/traverse.h). The block tests are the scalar tests lane for lane, ties to the
// later lane, so a leaf's hit is the one its triangles tested in order would give. A Counter other than NoCount
// records what the ray visited, as in kernels/traverse.h: real triangles, and the blocks' bytes, padding included.
//
// Robustness. The triangle tests round: a hit they report may lie off the exact ray by a few ulps of the scene's
// extent, so outside every voxel the exact ray crosses. Each ray therefore pads its voxels by kRobustPad R in
// space, R bounding the distance from its origin to any point of the scene (half the scene's largest extent plus
// the origin's distance from its centre), as the BVH kernels pad their boxes (kernels/traverse.h's SlabRay):
// a plane crossing becomes the interval t_plane -+ kRobustPad R |1 / dir|. Plane distances are computed in
// double, (split - org) * (1 / dir), within 3 * 2^-53 of the exact quotient and never overflowing, and widened
// by kKdWiden of themselves besides. A zero direction component (+0 or -0) never divides: the ray's coordinate is
// constant, a plane farther than the pad is on one side exactly, and a ray in the padded plane visits both
// children. Hits are accepted wherever the triangle test finds them in (tmin, hit.t], not only inside the current
// leaf's interval, and the search ends once the nearest pending node starts past the hit (with kKdCullSlack): a
// triangle stored in several leaves is found first in the nearest of them, its repeats in farther leaves re-find
// the same hit, and the answer is brute force's (the same triangle test over every triangle), including rays
// that lie in or start on a split plane or leave a leaf exactly at its far plane.
#include "accel/kdtree.h"
#include "kernels/traverse.h"

#include <cmath>

namespace canopy {

// Relative widening of every plane distance: far above the 3 * 2^-53 error of the double computation.
constexpr double kKdWiden = 0x1p-40;
// Relative slack of the final cut: a pending node is skipped only when it starts beyond hit.t (1 + slack), so a
// triangle whose computed t rounds below its exact crossing is still found (the watertight test's t is exact to a
// few ulps on well-shaped triangles; 2^-16 leaves room for edge-on ones).
constexpr double kKdCullSlack = 0x1p-16;

namespace detail {

struct KdRay {
    double org[3], inv[3];
    double pad[3];  // the spatial pad kRobustPad R in t along each axis (zero axes: in space)
    bool zero[3];   // a ±0 direction component: that coordinate is constant along the ray
    bool dir_positive[3];

    KdRay(const Ray& ray, const BBox& bounds) {
        double half_extent = 0, offset = 0;
        for (int k = 0; k < 3; ++k) {
            const double centre = 0.5 * (double(bounds.lower[k]) + double(bounds.upper[k]));
            half_extent = std::max(half_extent, 0.5 * (double(bounds.upper[k]) - double(bounds.lower[k])));
            offset = std::max(offset, std::abs(double(ray.org[k]) - centre));
        }
        const double reach = double(kRobustPad) * (half_extent + offset);
        for (int k = 0; k < 3; ++k) {
            org[k] = ray.org[k];
            zero[k] = ray.dir[k] == 0.0f;
            inv[k] = zero[k] ? 0.0 : 1.0 / double(ray.dir[k]);
            pad[k] = zero[k] ? reach : reach * std::abs(inv[k]);
            dir_positive[k] = ray.dir[k] > 0.0f;
        }
    }
};

// The interval of t where the ray may be in the plane (axis k, position p): its crossing, padded.
inline void plane_interval(const KdRay& r, int k, double p, double& lo, double& hi) {
    const double t = (p - r.org[k]) * r.inv[k];
    const double margin = r.pad[k] + std::abs(t) * kKdWiden;
    lo = t - margin, hi = t + margin;
}

// The ray's interval in the scene's (padded) bounds, intersected with [t0, t1]; false when it is empty.
inline bool clip_to_bounds(const KdRay& r, const BBox& bounds, double& t0, double& t1) {
    for (int k = 0; k < 3; ++k) {
        if (r.zero[k]) {
            if (r.org[k] < bounds.lower[k] - r.pad[k] || r.org[k] > bounds.upper[k] + r.pad[k]) return false;
            continue;
        }
        double lo_a, hi_a, lo_b, hi_b;
        plane_interval(r, k, bounds.lower[k], lo_a, hi_a);
        plane_interval(r, k, bounds.upper[k], lo_b, hi_b);
        t0 = std::max(t0, std::min(lo_a, lo_b));
        t1 = std::min(t1, std::max(hi_a, hi_b));
    }
    return t0 <= t1;
}

struct KdStackEntry {
    uint32_t node;
    double t0, t1;
};

}  // namespace detail

// Closest hit (Query::Closest) or any hit (Query::Any) in (kernel_tmin(ray), ray.tmax], as kernels/traverse.h's
// traverse() answers for a BVH. For Any, `hit` holds the first hit found.
template <Query Q, class TriangleTest = WatertightRay, class Counter = NoCount>
[[gnu::noinline]] bool traverse_kd(const KdTree& tree, const Ray& ray, Hit& hit, Counter&& counter = {}) {
    hit = Hit{};
    hit.t = ray.tmax;
    const float tmin = kernel_tmin(ray);
    // A NaN, infinite or zero direction, or a non-finite origin, hits nothing in the triangle tests either.
    bool finite = true;
    for (int k = 0; k < 3; ++k) finite &= std::isfinite(ray.dir[k]) && std::isfinite(ray.org[k]);
    if (tree.nodes.empty() || !finite || ray.dir == Vec3(0.0f) || !(tmin <= ray.tmax)) return false;
    const detail::KdRay r(ray, tree.bounds);
    double t0 = tmin, t1 = ray.tmax;
    if (!detail::clip_to_bounds(r, tree.bounds, t0, t1)) return false;
    const KdNode* const nodes = tree.nodes.data();
    const TriangleTest test(ray);  // set up once the ray meets the scene's bounds
    detail::KdStackEntry stack[kKdMaxDepth + 1];
    int sp = 0;
    uint32_t index = 0;
    for (;;) {
        const KdNode* node = &nodes[index];
        while (!node->is_leaf()) {
            counter.inner();
            counter.touch(node, sizeof(KdNode));
            const int k = node->axis();
            const uint32_t below = index + 1, above = node->above();
            const double split = node->split;
            if (r.zero[k]) {  // parallel to the plane: one side, or both when lying in the padded plane
                const double gap = r.org[k] - split;
                if (std::abs(gap) <= r.pad[k]) stack[sp++] = {above, t0, t1};
                index = gap <= r.pad[k] ? below : above;
                node = &nodes[index];
                continue;
            }
            double lo, hi;
            detail::plane_interval(r, k, split, lo, hi);
            // Before the crossing (t < t_plane, whatever the origin's side) the ray is on the side its direction
            // leaves, after it on the side it points to.
            const uint32_t first = r.dir_positive[k] ? below : above, second = r.dir_positive[k] ? above : below;
            if (hi < t0) {
                index = second;
            } else if (lo > t1) {
                index = first;
            } else {
                stack[sp++] = {second, std::max(t0, lo), t1};
                index = first;
                t1 = std::min(t1, hi);
            }
            node = &nodes[index];
        }
        counter.leaf();
        const uint32_t count = node->count();
        counter.triangles(count);
        if (const uint32_t blocks = kd_blocks(count)) {
            const KdBlock* block = tree.leaf_blocks.data() + node->first;
            counter.touch(block, sizeof(KdBlock) * blocks);
            for (uint32_t b = 0; b < blocks; ++b)
                if (test.intersect_block(block[b], tmin, hit) >= 0 && Q == Query::Any) return true;
        }
        const double cut = double(hit.t) + std::abs(double(hit.t)) * kKdCullSlack;
        do {
            if (sp == 0) return hit.found();
            --sp;
        } while (stack[sp].t0 > cut);
        index = stack[sp].node;
        t0 = stack[sp].t0;
        t1 = std::min(stack[sp].t1, cut);
    }
}

template <class TriangleTest = WatertightRay>
bool any_hit_kd(const KdTree& tree, const Ray& ray) {
    Hit hit;
    return traverse_kd<Query::Any, TriangleTest>(tree, ray, hit);
}

}  // namespace canopy
