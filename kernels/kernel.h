#pragma once
// A kernel is a built tree with its traversal's compile-time modes: a small value type whose queries the path
// tracers, the tools and the tests call directly, so that choosing one costs a dispatch per frame, not per ray.
#include "accel/compressed_wide_bvh.h"
#include "accel/kdtree.h"
#include "kernels/traverse.h"
#include "kernels/traverse_kd.h"
#include "kernels/traverse_stream.h"
#include "kernels/traverse_two_level.h"

#include <span>
#include <type_traits>

namespace canopy {

// One flat tree over the scene's triangles, whose leaves hold those triangles.
template <class Layout>
constexpr bool is_flat_layout = std::is_same_v<Layout, WideBvh<Layout::kWidth>> ||
                                std::is_same_v<Layout, CompressedWideBvh<Layout::kWidth>>;
// The batch kernels (packets, streams) walk standard nodes; a compressed tree answers a batch ray by ray.
template <class Layout>
constexpr bool has_batch_kernels = !std::is_same_v<Layout, CompressedWideBvh<Layout::kWidth>>;

// The stream tracer's batches of a kernel without a packet form need no scratch.
struct NoScratch {
    size_t bytes() const { return 0; }
};

template <class Layout, bool Robust, class TriangleTest>
struct BvhKernel {
    static constexpr int kWidth = Layout::kWidth;
    static constexpr bool kRobust = Robust;
    using Test = TriangleTest;
    static constexpr bool kBatches = has_batch_kernels<Layout>;
    static constexpr bool kStreams = kBatches;  // the stream tracer wants packets: a compressed tree has none
    using Scratch = std::conditional_t<kBatches, StreamScratch<kWidth>, NoScratch>;
    const Layout& bvh;

    template <Query Q = Query::Closest, class Counter = NoCount>
    bool query(const Ray& ray, Hit& hit, Counter&& counter = {}) const {
        return traverse<Q, Robust, TriangleTest>(bvh, ray, hit, std::forward<Counter>(counter));
    }
    bool closest(const Ray& ray, Hit& hit) const { return closest_hit<Robust, TriangleTest>(bvh, ray, hit); }
    // A flat tree hands over the hit triangle's corners from the leaf it has just read, which saves the shading a
    // read of the scene's triangle (docs/results.md#shading-from-the-leaf).
    bool closest(const Ray& ray, Hit& hit, Triangle& corners) const
        requires is_flat_layout<Layout>
    {
        NearestCorners<kWidth> nearest;
        if (!traverse<Query::Closest, Robust, TriangleTest>(bvh, ray, hit, nearest)) return false;
        corners = nearest.triangle();
        return true;
    }
    // A two-level tree's likewise, a transformed instance's corners taken to world space: shading's point and normal
    // then round differently from the flat scene's copy by a few ulps (statistics agree, not bits).
    bool closest(const Ray& ray, Hit& hit, Triangle& corners) const
        requires std::is_same_v<Layout, TwoLevelBvh<kWidth>>
    {
        NearestPlacedCorners<kWidth> nearest;
        if (!traverse<Query::Closest, Robust, TriangleTest>(bvh, ray, hit, nearest)) return false;
        corners = nearest.triangle();
        if (nearest.instance != kWorldSpace) {
            const glm::mat4& m = bvh.to_world[nearest.instance];
            corners = {Vec3(m * glm::vec4(corners.v0, 1.0f)), Vec3(m * glm::vec4(corners.v1, 1.0f)), Vec3(m * glm::vec4(corners.v2, 1.0f))};
        }
        return true;
    }
    template <Query Q>
    void batch(std::span<const Ray> rays, std::span<Hit> hits, Scratch& scratch, BatchTraversal how) const {
        if constexpr (kBatches) {
            traverse_batch<Q, Robust, TriangleTest>(bvh, rays, hits, scratch, how);
        } else {
            for (size_t i = 0; i < rays.size(); ++i) query<Q>(rays[i], hits[i]);
        }
    }
};

// The kd-tree's kernel: one ray at a time, batches included.
template <class TriangleTest>
struct KdKernel {
    using Scratch = NoScratch;
    static constexpr bool kBatches = false;
    static constexpr bool kStreams = true;  // its batches ray by ray, as the stream tracer's reference
    const KdTree& tree;

    template <Query Q = Query::Closest, class Counter = NoCount>
    bool query(const Ray& ray, Hit& hit, Counter&& counter = {}) const {
        return traverse_kd<Q, TriangleTest>(tree, ray, hit, std::forward<Counter>(counter));
    }
    bool closest(const Ray& ray, Hit& hit) const { return query(ray, hit); }
    template <Query Q>
    void batch(std::span<const Ray> rays, std::span<Hit> hits, Scratch&, BatchTraversal) const {
        for (size_t i = 0; i < rays.size(); ++i) query<Q>(rays[i], hits[i]);
    }
};

}  // namespace canopy
