#pragma once
// Batch queries: closest or any hit for a span of rays, each ray's answer exactly the single-ray kernel's. A batch
// is traced ray by ray by the single-ray kernel (BatchTraversal::Single), or, for flat trees, in packets of 16 rays
// (BatchTraversal::Packet, traverse_packet.h; 8 without AVX-512) or as a ray stream (BatchTraversal::Stream). On the
// wavefront tracer's sorted diffuse path rays, 16-ray hybrid packets traced fastest (see kPacketSwitch), ray streams
// slowest, slower than the single-path tracer at every chunk size and fallback threshold tried, and 8-ray AVX2
// packets no faster than single rays (docs/results.md#tracers-single-and-stream). Packet is the default; Single and
// Stream are kept, tested, for comparison and further work.
//
// Flat trees are walked by a ray stream (Barringer and Akenine-Möller 2014, "Dynamic Ray Stream Traversal", sec. 3,
// with wide nodes): a node is visited once for all the rays that reach it; each of those rays is tested against
// the node's N children with the single-ray node test, and the stream is split into one list per child hit,
// visited nearest first (by the rays' mean entry distance). A list shorter than kMinStreamRays falls back to the
// single-ray kernel from that node, where sharing a node's cache lines no longer pays for the lists. A ray tests
// every node with its own running far limit, so it reaches every leaf the single-ray kernel would test at that
// limit; the leaves it tests are the same triangles with the same arithmetic, and the closest hit is the same
// triangle at the same distance, unless two triangles tie exactly at that distance, when either may be returned.
//
// Two-level trees answer a batch one ray at a time in either mode (their instance entries transform each ray on its
// own).
#include "kernels/traverse.h"
#include "kernels/traverse_packet.h"
#include "kernels/traverse_two_level.h"

#include <algorithm>
#include <array>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy {

// A list shorter than this leaves the stream for the single-ray kernel.
constexpr uint32_t kMinStreamRays = 8;
// Rays walked together at most: the lists of one chunk, with its rays' slab data, stay in the L2 cache.
constexpr uint32_t kStreamChunk = 4096;

// Memory a stream traversal reuses from call to call: one per thread.
template <int N>
struct StreamScratch {
    struct Entry {
        uint32_t ray;
        float tnear;
    };
    struct Tested {
        uint32_t ray, mask;
        std::array<float, N> tnear;
    };
    struct Frame {
        detail::StackEntry node;
        uint32_t begin, end;  // the node's ray list in `lists`
    };
    std::vector<detail::SlabRay<N>> slabs;  // per ray of the chunk
    std::vector<float> tmin;
    std::vector<Entry> lists;  // the ray lists of the frames on `frames`, a stack of regions
    std::vector<Tested> tested;
    std::vector<Frame> frames;
    // Packets: a batch whose octant runs are too short for packets, grouped by octant, and where each ray came from.
    std::vector<Ray> grouped;
    std::vector<Hit> grouped_hits;
    std::vector<uint32_t> order;

    size_t bytes() const {
        return slabs.capacity() * sizeof(slabs[0]) + tmin.capacity() * sizeof(float) + lists.capacity() * sizeof(Entry) +
               tested.capacity() * sizeof(Tested) + frames.capacity() * sizeof(Frame) + grouped.capacity() * sizeof(Ray) +
               grouped_hits.capacity() * sizeof(Hit) + order.capacity() * sizeof(uint32_t);
    }
};

namespace detail {

// Whether most of a batch's rays lie in runs of one octant shorter than a packet takes (kPacketSwitch).
inline bool short_octant_runs(std::span<const Ray> rays) {
    constexpr size_t kWorthGrouping = 64;  // below, a batch's packets are few either way
    if (rays.size() < kWorthGrouping) return false;
    size_t in_short = 0, first = 0;
    for (size_t i = 1; i <= rays.size(); ++i)
        if (i == rays.size() || octant(rays[i]) != octant(rays[first])) {
            if (i - first < size_t(kPacketSwitch)) in_short += i - first;
            first = i;
        }
    return 2 * in_short > rays.size();
}

// `rays` into `grouped` by octant, each octant's rays in their order (a stable counting sort); grouped[i] is
// rays[order[i]].
inline void group_by_octant(std::span<const Ray> rays, std::vector<Ray>& grouped, std::vector<uint32_t>& order) {
    std::array<uint32_t, 9> start{};
    for (const Ray& r : rays) ++start[octant(r) + 1];
    for (size_t o = 1; o < start.size(); ++o) start[o] += start[o - 1];
    order.resize(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) order[start[octant(rays[i])]++] = uint32_t(i);
    grouped.resize(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) grouped[i] = rays[order[i]];
}

template <int N>
[[gnu::always_inline]] inline auto node_tmin(float tmin) {
    if constexpr (N == 2) return tmin;
    else return simd::Simd<N>::set1(tmin);
}

// Tests the rays of `frame` against `node`'s children and replaces the frame by one frame per child hit, the
// nearest child (least mean entry distance) on top. The child lists overwrite the parent's, which `tested` keeps.
template <int N, class Counter>
[[gnu::always_inline]] inline void split_stream(const WideNode<N>& node, const typename StreamScratch<N>::Frame& frame,
                                                std::span<const Hit> hits, StreamScratch<N>& s, Counter& counter) {
    const uint32_t count = frame.end - frame.begin;
    s.tested.resize(count);
    std::array<uint32_t, N> rays_of{};
    std::array<float, N> distance_sum{};
    for (uint32_t k = 0; k < count; ++k) {
        const uint32_t ray = s.lists[frame.begin + k].ray;
        counter.inner();
        typename StreamScratch<N>::Tested& t = s.tested[k];
        t.ray = ray;
        t.mask = intersect_children<N>(node, NodeRay<N>(s.slabs[ray]), node_tmin<N>(s.tmin[ray]), hits[ray].t, t.tnear);
        for (uint32_t m = t.mask; m; m &= m - 1) {
            const int i = std::countr_zero(m);
            ++rays_of[i];
            distance_sum[i] += t.tnear[i];
        }
    }
    // Far to near: the nearest child's list is allocated last, on top, and its frame popped first.
    std::array<int, N> order;
    int children = 0;
    for (int i = 0; i < N; ++i)
        if (rays_of[i]) order[children++] = i;
    std::sort(order.begin(), order.begin() + children, [&](int a, int b) {
        return distance_sum[a] * float(rays_of[b]) > distance_sum[b] * float(rays_of[a]);
    });
    std::array<uint32_t, N> cursor{};
    uint32_t top = frame.begin;
    for (int c = 0; c < children; ++c) {
        const int i = order[c];
        cursor[i] = top;
        s.frames.push_back({{node.child[i], node.count[i], 0.0f}, top, top + rays_of[i]});
        top += rays_of[i];
    }
    s.lists.resize(top);
    for (uint32_t k = 0; k < count; ++k) {
        const typename StreamScratch<N>::Tested& t = s.tested[k];
        for (uint32_t m = t.mask; m; m &= m - 1) {
            const int i = std::countr_zero(m);
            s.lists[cursor[i]++] = {t.ray, t.tnear[i]};
        }
    }
}

template <Query Q, bool Robust, class TriangleTest, int N, class Counter>
void trace_chunk(const WideBvh<N>& bvh, std::span<const Ray> rays, std::span<Hit> hits, StreamScratch<N>& s,
                 Counter& counter) {
    const uint32_t n = uint32_t(rays.size());
    s.slabs.resize(n);
    s.tmin.resize(n);
    s.lists.resize(n);
    for (uint32_t i = 0; i < n; ++i) {
        s.slabs[i] = SlabRay<N>(rays[i], bvh.frame, Robust);
        s.tmin[i] = kernel_tmin(rays[i]);
        s.lists[i] = {i, s.tmin[i]};
    }
    s.frames.assign(1, {{0, 0, 0.0f}, 0, n});
    while (!s.frames.empty()) {
        typename StreamScratch<N>::Frame frame = s.frames.back();
        s.frames.pop_back();
        // Rays whose far limit has come below their entry to this node (or, for any hit, that have a hit) drop out.
        uint32_t live = frame.begin;
        for (uint32_t k = frame.begin; k < frame.end; ++k) {
            const typename StreamScratch<N>::Entry e = s.lists[k];
            const bool done = Q == Query::Any ? hits[e.ray].found() : e.tnear > hits[e.ray].t;
            if (!done) s.lists[live++] = e;
        }
        frame.end = live;
        s.lists.resize(live);
        if (live - frame.begin < kMinStreamRays) {
            for (uint32_t k = frame.begin; k < live; ++k) {
                // Set up at once: a ray this deep in the tree nearly always reaches a leaf.
                const uint32_t ray = s.lists[k].ray;
                const TriangleTest test(rays[ray]);
                traverse_from<Q>(bvh, {frame.node.child, frame.node.count, s.lists[k].tnear}, s.slabs[ray], s.tmin[ray],
                                 hits[ray], counter, [&](const StackEntry& leaf) {
                                     return intersect_leaf(bvh, leaf, test, s.tmin[ray], hits[ray], counter);
                                 });
            }
        } else if (frame.node.count != 0) {
            for (uint32_t k = frame.begin; k < live; ++k) {
                const uint32_t ray = s.lists[k].ray;
                intersect_leaf(bvh, frame.node, TriangleTest(rays[ray]), s.tmin[ray], hits[ray], counter);
            }
        } else {
            split_stream<N>(bvh.nodes[frame.node.child], frame, hits, s, counter);
            continue;
        }
        s.lists.resize(frame.begin);
    }
}

}  // namespace detail

enum class BatchTraversal { Single, Packet, Stream };

// "single", "packet" or "stream"; throws std::invalid_argument naming the option for another name.
inline BatchTraversal parse_batch_traversal(const std::string& name) {
    if (name == "single") return BatchTraversal::Single;
    if (name == "packet") return BatchTraversal::Packet;
    if (name == "stream") return BatchTraversal::Stream;
    throw std::invalid_argument("--batch-traversal '" + name + "': known are single, packet, stream");
}

inline const char* batch_traversal_name(BatchTraversal how) {
    switch (how) {
        case BatchTraversal::Single: return "single";
        case BatchTraversal::Packet: return "packet";
        default: return "stream";
    }
}

// Closest hit (Query::Closest) or any hit (Query::Any) of every ray of `rays` into `hits` (same length), each
// ray's answer the single-ray traverse()'s (see the top of this file for exact ties).
template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
[[gnu::noinline]] void traverse_batch(const WideBvh<N>& bvh, std::span<const Ray> rays, std::span<Hit> hits,
                                      StreamScratch<N>& scratch, BatchTraversal how = BatchTraversal::Single,
                                      Counter&& counter = {}) {
    if (how == BatchTraversal::Single) return detail::trace_each<Q, Robust, TriangleTest>(bvh, rays, hits, counter);
    if (how == BatchTraversal::Packet) {
        if (!detail::short_octant_runs(rays)) return traverse_packets<Q, Robust, TriangleTest>(bvh, rays, hits, counter);
        // Rays in octant runs too short for a packet (ambient-occlusion probes, a few a point in pixel order) go to
        // the packets grouped by octant, each octant's in their order (docs/results.md#workloads-against-embrees-best-call).
        detail::group_by_octant(rays, scratch.grouped, scratch.order);
        scratch.grouped_hits.resize(rays.size());
        traverse_packets<Q, Robust, TriangleTest>(bvh, std::span<const Ray>(scratch.grouped), std::span<Hit>(scratch.grouped_hits), counter);
        for (size_t i = 0; i < rays.size(); ++i) hits[scratch.order[i]] = scratch.grouped_hits[i];
        return;
    }
    for (size_t i = 0; i < rays.size(); ++i) {
        hits[i] = Hit{};
        hits[i].t = rays[i].tmax;
    }
    if (bvh.nodes.empty()) return;
    for (size_t begin = 0; begin < rays.size(); begin += kStreamChunk) {
        const size_t n = std::min<size_t>(kStreamChunk, rays.size() - begin);
        detail::trace_chunk<Q, Robust, TriangleTest>(bvh, rays.subspan(begin, n), hits.subspan(begin, n), scratch, counter);
    }
}

template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
void traverse_batch(const TwoLevelBvh<N>& bvh, std::span<const Ray> rays, std::span<Hit> hits, StreamScratch<N>&,
                    BatchTraversal = BatchTraversal::Single, Counter&& counter = {}) {
    detail::trace_each<Q, Robust, TriangleTest>(bvh, rays, hits, counter);
}

}  // namespace canopy
