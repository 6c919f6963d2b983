#pragma once
// Traversal of a two-level BVH in every kernel width. The top level and the object trees share one pool
// (accel/two_level.h), so the world ray walks top-level nodes and directly linked object subtrees in one loop, as
// it would a single BVH (sec. 5.5). A top-level leaf flagged as instance entries enters an instance's object tree
// at the referenced node, with the ray transformed into the instance's object space unless the placement is the
// identity. A ray may thus be transformed into the same instance several times, which the paper finds cheaper
// than avoiding it (sec. 5.5); re-braiding opens transformed nodes only where that does not add entries.
#include "accel/two_level.h"
#include "kernels/traverse.h"

namespace canopy {
namespace detail {

// Traverses one object tree from `entry` with a ray already in its space; true when it recorded a hit.
// tri_ray() gives the triangle test of that ray, asked for at the first leaf only.
template <Query Q, int N, class TriangleRay, class Counter>
bool enter_object(const WideBvh<N>& pool, const TopLevelRef& entry, const SlabRay<N>& box_ray,
                  TriangleRay&& tri_ray, float tmin, Hit& hit, Counter& counter) {
    bool found = false;
    const auto leaf = [&](const StackEntry& at) __attribute__((always_inline)) {
        const bool here = intersect_leaf(pool, at, tri_ray(), tmin, hit, counter);
        found |= here;
        return here;
    };
    traverse_from<Q>(pool, {entry.child, entry.count, tmin}, box_ray, tmin, hit, counter, leaf);
    return found;
}

// The top-level leaf `leaf`, a run of instance entries: each entered with the ray in its instance's space. Out
// of line, so the instanced loop stays small (docs/results.md#traversal-kernels). world_tri() gives the world
// ray's triangle test.
template <Query Q, bool Robust, class TriangleTest, int N, class Counter, class WorldTri>
[[gnu::noinline]] bool enter_instances(const TwoLevelBvh<N>& bvh, const StackEntry& leaf, const Ray& ray, float tmin,
                                       const SlabRay<N>& world_box, WorldTri&& world_tri, Hit& hit, Counter& counter) {
    bool found = false;
    const uint32_t end = leaf.child + (leaf.count & ~TwoLevelBvh<N>::kInstanceEntries);
    for (uint32_t i = leaf.child; i < end; ++i) {
        const TopLevelRef& entry = bvh.entries[i];
        const PlacedObject& instance = bvh.instances[entry.instance];
        bool here;
        if (instance.identity) {
            here = enter_object<Q>(bvh.pool, entry, world_box, world_tri, tmin, hit, counter);
        } else {
            // Direction is not renormalised, so distances along the ray stay world distances. The triangle test's
            // setup waits for a leaf: most entries miss every box below them (docs/results.md#traversal-kernels).
            const Ray local{instance.point(ray.org), instance.vector(ray.dir), tmin, hit.t};
            LazyTest<TriangleTest> local_tri;
            const SlabRay<N> local_box(local, bvh.objects[instance.object].frame, Robust);
            const auto local_test = [&]() __attribute__((always_inline)) -> const TriangleTest& {
                return local_tri.get(local);
            };
            counter.placed(entry.instance);
            here = enter_object<Q>(bvh.pool, entry, local_box, local_test, tmin, hit, counter);
            counter.placed(kWorldSpace);
        }
        if (here) hit.prim += instance.prim_offset;
        found |= here;
        if (found && Q == Query::Any) return true;
    }
    return found;
}

// Every top-level leaf is a direct link or a run of instance entries, each entered with the instance's ray.
// Out of line: see traverse().
template <Query Q, bool Robust, class TriangleTest, int N, class Counter>
[[gnu::noinline]] void traverse_instanced(const TwoLevelBvh<N>& bvh, const Ray& ray, Hit& hit, Counter& counter) {
    const SlabRay<N> world_box(ray, bvh.pool.frame, Robust);
    LazyTest<TriangleTest> world_test;  // set up at the first leaf the world ray reaches
    const auto world_tri = [&]() __attribute__((always_inline)) -> const TriangleTest& { return world_test.get(ray); };
    const float tmin = kernel_tmin(ray);
    const auto leaf = [&](const StackEntry& at) __attribute__((always_inline)) {
        if (at.count & TwoLevelBvh<N>::kInstanceEntries)
            return enter_instances<Q, Robust, TriangleTest>(bvh, at, ray, tmin, world_box, world_tri, hit, counter);
        return intersect_leaf(bvh.pool, at, world_tri(), tmin, hit, counter);  // a directly linked leaf
    };
    traverse_from<Q>(bvh.pool, {bvh.root, 0, tmin}, world_box, tmin, hit, counter, leaf);
}

// A structure without instance entries (every BRef of a direct() placement, as in a scene of one file's objects)
// is walked by the flat kernel's own loop from the top level's root: the instanced loop, whose call to
// enter_instances is never taken there, traced such a structure slower than the flat tree, this one faster
// (docs/results.md#traversal-kernels).
template <Query Q, bool Robust, class TriangleTest, int N, class Counter>
[[gnu::noinline]] void traverse_direct(const TwoLevelBvh<N>& bvh, const Ray& ray, Hit& hit, Counter& counter) {
    traverse_tree<Q, Robust, TriangleTest, N>(bvh.pool, bvh.root, bvh.bounds, bvh.pool.frame, ray, hit, counter);
}

}  // namespace detail

template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
bool traverse(const TwoLevelBvh<N>& bvh, const Ray& ray, Hit& hit, Counter&& counter = {}) {
    hit = Hit{};
    hit.t = ray.tmax;
    if (bvh.brefs == 0) return false;
    if (bvh.entries.empty()) detail::traverse_direct<Q, Robust, TriangleTest>(bvh, ray, hit, counter);
    else detail::traverse_instanced<Q, Robust, TriangleTest>(bvh, ray, hit, counter);
    return hit.found();
}

template <bool Robust = true, class TriangleTest = WatertightRay, int N>
bool closest_hit(const TwoLevelBvh<N>& bvh, const Ray& ray, Hit& hit) {
    return traverse<Query::Closest, Robust, TriangleTest>(bvh, ray, hit);
}

template <bool Robust = true, class TriangleTest = WatertightRay, int N>
bool any_hit(const TwoLevelBvh<N>& bvh, const Ray& ray) {
    Hit hit;
    return traverse<Query::Any, Robust, TriangleTest>(bvh, ray, hit);
}

}  // namespace canopy
