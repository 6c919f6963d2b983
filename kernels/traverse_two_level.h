#pragma once
// Traversal of a two-level BVH in every kernel width: the top level with the world ray; at each of its leaves
// the ray enters the referenced object tree at that node (a re-braided top level points below object roots),
// transformed into the instance's object space unless the instance is placed by the identity. A ray may thus be
// transformed into the same instance several times, which the paper finds cheaper than avoiding it (sec. 5.5).
#include "accel/two_level.h"
#include "kernels/traverse.h"

namespace canopy {
namespace detail {

// Traverses one object tree from `entry` with a ray already in its space; true when it recorded a hit.
template <Query Q, bool Robust, class TriangleTest, int N, class Counter>
bool enter_object(const WideBvh<N>& object, const TopLevelRef& entry, const SlabRay<N>& box_ray,
                  const TriangleTest& tri_ray, float tmin, Hit& hit, Counter& counter) {
    bool found = false;
    traverse_from<Q, Robust>(object, {entry.child, entry.count, tmin}, box_ray, tmin, hit, counter,
                             [&](const StackEntry& leaf) {
                                 const bool here = intersect_leaf(object, leaf, tri_ray, tmin, hit, counter);
                                 found |= here;
                                 return here;
                             });
    return found;
}

}  // namespace detail

template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
bool traverse(const TwoLevelBvh<N>& bvh, const Ray& ray, Hit& hit, Counter&& counter = {}) {
    hit = Hit{};
    hit.t = ray.tmax;
    if (bvh.nodes.empty()) return false;
    const detail::SlabRay<N> world_box(ray);
    const TriangleTest world_tri(ray);
    detail::traverse_from<Q, Robust>(bvh, {0, 0, ray.tmin}, world_box, ray.tmin, hit, counter,
                                     [&](const detail::StackEntry& leaf) {
        bool found = false;
        for (uint32_t i = leaf.child; i < leaf.child + leaf.count; ++i) {
            const TopLevelRef& entry = bvh.leaves[i];
            const PlacedObject& instance = bvh.instances[entry.instance];
            const WideBvh<N>& object = bvh.objects[instance.object];
            bool here;
            if (instance.identity) {
                here = detail::enter_object<Q, Robust>(object, entry, world_box, world_tri, ray.tmin, hit, counter);
            } else {
                // Direction is not renormalised, so distances along the ray stay world distances.
                const Ray local{instance.point(ray.org), instance.vector(ray.dir), ray.tmin, hit.t};
                here = detail::enter_object<Q, Robust>(object, entry, detail::SlabRay<N>(local), TriangleTest(local),
                                                       ray.tmin, hit, counter);
            }
            if (here) hit.prim += instance.prim_offset;
            found |= here;
            if (found && Q == Query::Any) return true;
        }
        return found;
    });
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
