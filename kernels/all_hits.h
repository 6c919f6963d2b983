#pragma once
// Every hit along a ray, not only the nearest: the walk of a flat tree (WideBvh<N>, any width) into every child box
// the ray crosses in its whole interval, each leaf triangle tested with the kernels' own triangle test, so a hit
// here is a hit of the closest-hit kernel at the same distance. For counting crossings (inside tests) and for
// listing a ray's hits in order; nothing is sorted here.
#include "accel/wide_bvh.h"
#include "kernels/traverse.h"


namespace canopy {

// A leaf entry's triangles with their scene ids: one for a binary tree's LeafTriangle, a block's occupied lanes.
template <class F>
void for_each_leaf_triangle(const LeafTriangle& t, F&& f) {
    f(Triangle{t.v0, t.v1, t.v2}, t.prim);
}
template <int W, class F>
void for_each_leaf_triangle(const TriangleBlock<W>& block, F&& f) {
    for (int lane = 0; lane < W; ++lane) {
        if (block.prim[lane] == TriangleBlock<W>::kNone) continue;
        const auto corner = [&](int v) { return Vec3(block.v[v][0][lane], block.v[v][1][lane], block.v[v][2][lane]); };
        f(Triangle{corner(0), corner(1), corner(2)}, block.prim[lane]);
    }
}

// Calls on_hit(hit, corners) for every triangle the ray hits in (kernel_tmin(ray), ray.tmax]. A triangle may be
// reported more than once: the one-triangle leaves of a wide node share a block (accel/wide_bvh.h), which every one
// of them hands over whole, so callers that count or list hits drop repeats of a triangle id.
template <bool Robust, class TriangleTest, int N, class OnHit>
void for_each_hit(const WideBvh<N>& bvh, const Ray& ray, OnHit&& on_hit) {
    if (bvh.nodes.empty()) return;
    const detail::SlabRay<N> box_ray(ray, bvh.frame, Robust);
    const detail::NodeRay<N> lanes(box_ray);
    const float tmin = kernel_tmin(ray);
    const TriangleTest test(ray);
    detail::StackEntry stack[kMaxBvhDepth * (N - 1) + 1];
    detail::StackEntry* sp = stack;
    *sp++ = {0, 0, tmin};
    while (sp != stack) {
        const detail::StackEntry entry = *--sp;
        if (entry.count == 0) {
            const WideNode<N>& node = bvh.nodes[entry.child];
            std::array<float, N> tnear;
            uint32_t mask;
            if constexpr (N == 2) mask = detail::intersect_children<N>(node, box_ray, tmin, ray.tmax, tnear);
            else mask = detail::intersect_children<N>(node, lanes, simd::Simd<N>::set1(tmin), ray.tmax, tnear);
            for (; mask; mask &= mask - 1) {
                const size_t i = detail::lowest_lane(mask);
                *sp++ = {node.child[i], node.count[i], tnear[i]};
            }
            continue;
        }
        const uint32_t end = entry.child + (N == 2 ? entry.count : leaf_entries(N, entry.count));
        for (uint32_t e = entry.child; e < end; ++e)
            for_each_leaf_triangle(bvh.leaves[e], [&](const Triangle& t, uint32_t prim) {
                Hit hit;
                hit.t = ray.tmax;
                if (test.intersect(t.v0, t.v1, t.v2, prim, tmin, hit)) on_hit(hit, t);
            });
    }
}

}  // namespace canopy
