#pragma once
// Stack-based traversal of a WideBvh<N>: children tested in one pass, visited near to far.
// Robust = true pads the far slab distance so rounding never culls a box the ray crosses
// (Ize 2013, "Robust BVH Ray Traversal"); Robust = false is the fast mode.
#include "accel/wide_bvh.h"
#include "kernels/watertight.h"

#include <immintrin.h>

#include <array>
#include <bit>

namespace canopy {

// 1 + 2 gamma(3), gamma(n) = n u / (1 - n u) with u = 2^-24 (Ize 2013, sec. 3; pbrt-v4 eq. 6.21)
constexpr float kRobustFarScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

enum class Query { Closest, Any };

namespace detail {

// Per-ray slab data: the origin, reciprocal direction, and for each axis the offsets of the near and far
// planes in WideNode::planes, chosen once by the direction's sign.
template <int N>
struct SlabRay {
    Vec3 org, inv_dir;
    int near[3], far[3];

    explicit SlabRay(const RayBoxData& r) : org(r.org), inv_dir(r.inv_dir) {
        for (int a = 0; a < 3; ++a) {
            const bool positive = !std::signbit(inv_dir[a]);
            near[a] = (positive ? 0 : 3 * N) + a * N;
            far[a] = (positive ? 3 * N : 0) + a * N;
        }
    }
};

// Slab test of every child box against [tmin, tmax]; returns a bit mask of the children hit and
// their entry distances. A NaN from 0 * inf (origin on a slab plane, direction parallel to it) never
// replaces the running interval, so such rays count as touching the box: conservative.
template <bool Robust, int N>
inline uint32_t intersect_children(const WideNode<N>& node, const SlabRay<N>& r, float tmin, float tmax,
                                   std::array<float, N>& tnear) {
    const float* planes = node.planes;
    uint32_t mask = 0;
    for (int i = 0; i < N; ++i) {
        float t0 = tmin, far = std::numeric_limits<float>::infinity();
        for (int a = 0; a < 3; ++a) {
            const float near_a = (planes[r.near[a] + i] - r.org[a]) * r.inv_dir[a];
            const float far_a = (planes[r.far[a] + i] - r.org[a]) * r.inv_dir[a];
            t0 = near_a > t0 ? near_a : t0;
            far = far_a < far ? far_a : far;
        }
        if constexpr (Robust) far *= kRobustFarScale;  // padding is monotone: scaling the minimum suffices
        const float t1 = far < tmax ? far : tmax;
        tnear[i] = t0;
        mask |= uint32_t(t0 <= t1) << i;
    }
    return mask;
}

struct StackEntry {
    uint32_t child, count;  // as in WideNode: count 0 is an inner node
    float tnear;
};

template <int N>
inline void prefetch(const WideBvh<N>& bvh, const StackEntry& e) {
    if (e.count == 0) _mm_prefetch(reinterpret_cast<const char*>(&bvh.nodes[e.child]), _MM_HINT_T0);
    else _mm_prefetch(reinterpret_cast<const char*>(&bvh.triangles[e.child]), _MM_HINT_T0);
}

}  // namespace detail

// Closest hit (Query::Closest) or any hit (Query::Any) in (ray.tmin, ray.tmax]. For Any, `hit` holds
// the first hit found, not the closest.
template <Query Q, bool Robust = true, int N>
bool traverse(const WideBvh<N>& bvh, const Ray& ray, Hit& hit) {
    hit = Hit{};
    hit.t = ray.tmax;
    if (bvh.nodes.empty()) return false;
    const detail::SlabRay<N> box_ray{RayBoxData(ray)};
    const WatertightRay tri_ray(ray);
    std::array<detail::StackEntry, kMaxBvhDepth * (N - 1) + 1> stack;
    int sp = 0;
    detail::StackEntry current{0, 0, ray.tmin};
    for (;;) {
        if (current.count == 0) {
            const WideNode<N>& node = bvh.nodes[current.child];
            std::array<float, N> tnear;
            uint32_t mask = detail::intersect_children<Robust, N>(node, box_ray, ray.tmin, hit.t, tnear);
            if (mask && (mask & (mask - 1)) == 0) {  // one child hit: go there directly
                const int only = std::countr_zero(mask);
                current = {node.child[only], node.count[only], tnear[only]};
                continue;
            }
            if (N == 2 && mask == 3) {  // binary: go to the nearer child, keep the farther
                const int near = tnear[1] < tnear[0];
                stack[sp++] = {node.child[1 - near], node.count[1 - near], tnear[1 - near]};
                prefetch(bvh, stack[sp - 1]);  // its fetch overlaps the near subtree's work
                current = {node.child[near], node.count[near], tnear[near]};
                continue;
            }
            if (mask) {
                // Push all hit children far to near by insertion into the stack top, then take the nearest.
                const int base = sp;
                for (int i = 0; mask; ++i, mask >>= 1) {
                    if (!(mask & 1)) continue;
                    detail::StackEntry e{node.child[i], node.count[i], tnear[i]};
                    int j = sp++;
                    for (; j > base && stack[j - 1].tnear < e.tnear; --j) stack[j] = stack[j - 1];
                    stack[j] = e;
                }
                current = stack[--sp];
                continue;
            }
        } else {
            for (uint32_t i = current.child; i < current.child + current.count; ++i) {
                const LeafTriangle& t = bvh.triangles[i];
                if (tri_ray.intersect(t.v0, t.v1, t.v2, t.prim, ray.tmin, hit) && Q == Query::Any) return true;
            }
        }
        do {
            if (sp == 0) return hit.found();
            current = stack[--sp];
        } while (current.tnear > hit.t);
    }
}

template <bool Robust = true, int N>
bool closest_hit(const WideBvh<N>& bvh, const Ray& ray, Hit& hit) {
    return traverse<Query::Closest, Robust>(bvh, ray, hit);
}

template <bool Robust = true, int N>
bool any_hit(const WideBvh<N>& bvh, const Ray& ray) {
    Hit hit;
    return traverse<Query::Any, Robust>(bvh, ray, hit);
}

}  // namespace canopy
