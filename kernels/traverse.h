#pragma once
// Stack-based traversal of a WideBvh<N> or a CompressedWideBvh<N>, one template for every width and layout:
// children tested in one pass (scalar for N = 2, SSE for N = 4, AVX for N = 8), visited near to far. Robust = true
// pads the slab distances so rounding never culls a box the ray crosses (see SlabRay); Robust = false is the fast
// mode. TriangleTest is WatertightRay (default) or MollerTrumboreRay (fast mode). A Counter other than NoCount records inner nodes,
// leaves and triangles visited; with NoCount the calls compile to nothing.
#include "accel/compressed_wide_bvh.h"
#include "accel/wide_bvh.h"
#include "kernels/moller_trumbore.h"
#include "kernels/simd.h"
#include "kernels/watertight.h"

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <limits>
#include <new>
#include <type_traits>

namespace canopy {

// Robust mode's padding of the slab distances, relative to R |inv_dir| (see SlabRay): 8 u, u = 2^-24, twice the
// rounding bound it covers; twice that again made rays far from the origin much slower
// (docs/results.md#traversal-kernels).
constexpr float kRobustPad = 0x1p-21f;

// The smallest direction component the slab test divides by; smaller ones, zeros included, count as this with
// their sign, so every axis keeps culling (see SlabRay).
constexpr float kMinSlabDir = 0x1p-64f;

// The start of the interval every kernel searches, (tmin, tmax]: ray.tmin, or +0 when that is negative, -0 or
// NaN. Rays start at their origin, and the node test's comparisons by bits need a start of +0 or more (see
// intersect_children).
[[gnu::always_inline]] inline float kernel_tmin(const Ray& ray) { return ray.tmin > 0.0f ? ray.tmin : 0.0f; }

enum class Query { Closest, Any };

struct NoCount {
    void inner() {}
    void leaf() {}
    void triangles(uint32_t) {}
    void touch(const void*, size_t) {}
    template <class Leaf>
    void nearer_hit(const Leaf&, int) {}  // a leaf entry's triangle (the block's lane) became the nearest hit
    void placed(uint32_t) {}  // two-level: the leaves from here on are instance i's (kWorldSpace: the world's)
};

constexpr uint32_t kWorldSpace = ~0u;

// Counts nothing, but keeps the leaf entry of the nearest hit, which the traversal has just read: a renderer
// that shades the hit reads its corners from there, in cache, rather than from the scene's triangle array, a
// cache miss on every hit (docs/results.md#headline-binned-and-sbvh-against-embree). The corners are the scene
// triangle's, bit for bit. In a two-level tree, the leaves of a transformed instance hold its object's triangles in
// object space: NearestPlacedCorners keeps which instance that was.
template <int N>
struct NearestCorners : NoCount {
    const LeafOf<N>* entry = nullptr;
    int lane = 0;
    void nearer_hit(const LeafOf<N>& e, int l) { entry = &e, lane = l; }
    Triangle triangle() const {
        if constexpr (N == 2) {
            return {entry->v0, entry->v1, entry->v2};
        } else {
            const auto corner = [&](int v) { return Vec3(entry->v[v][0][lane], entry->v[v][1][lane], entry->v[v][2][lane]); };
            return {corner(0), corner(1), corner(2)};
        }
    }
};

// NearestCorners in a two-level tree: also the instance whose object space the nearest hit's corners are in.
template <int N>
struct NearestPlacedCorners : NearestCorners<N> {
    uint32_t current = kWorldSpace, instance = kWorldSpace;
    void placed(uint32_t i) { current = i; }
    void nearer_hit(const LeafOf<N>& e, int l) { NearestCorners<N>::nearer_hit(e, l), instance = current; }
};

// What a ray visited in the single-ray kernels, and the 64-byte cache lines its nodes and leaves span (the memory
// a visit reads, whatever the layout: a BVH8 node is 4 lines, a block of 8 triangles 5).
struct TraversalCounts {
    uint64_t inner_nodes = 0, leaf_nodes = 0, triangle_tests = 0, cache_lines = 0;
    void inner() { ++inner_nodes; }
    void leaf() { ++leaf_nodes; }
    void triangles(uint32_t n) { triangle_tests += n; }
    void touch(const void* p, size_t bytes) {
        const auto first = reinterpret_cast<uintptr_t>(p);
        cache_lines += (first + bytes - 1) / 64 - first / 64 + 1;
    }
    template <class Leaf>
    void nearer_hit(const Leaf&, int) {}
    void placed(uint32_t) {}
    TraversalCounts& operator+=(const TraversalCounts& o) {
        inner_nodes += o.inner_nodes, leaf_nodes += o.leaf_nodes, triangle_tests += o.triangle_tests;
        cache_lines += o.cache_lines;
        return *this;
    }
};

namespace detail {

// Per-ray slab data. Every slab distance is one FMA, plane * inv_dir + add, as in Embree's default traversal,
// with `add` = -org * inv_dir; the near and far planes of each axis are reached by offsets into
// WideNode::planes chosen once by the direction's sign.
//
// Planes and origin are in the tree's PlaneFrame: the origin is translated once, org - frame.origin, so R below
// measures the tree's extent, not its distance from the coordinate origin, and a small scene far out (the
// accuracy sphere, radius 100, at offset 1e7) traces as fast as at the origin. Distances stay world distances.
//
// Robust mode (Ize 2013's guarantee, "Robust BVH Ray Traversal", by other means) lowers the near planes' addend
// and raises the far planes' by pad = kRobustPad R |inv_dir|, R = P + |org| with P and |org| the largest
// magnitudes of the tree's plane coordinates (frame.bound) and of the translated origin's. Against the exact
// (plane - org) / dir, the FMA form rounds 1/dir, the padded origin org -+ reach (pad = reach |inv_dir|), its
// product with inv_dir and the FMA itself: errors of u times (|plane| + |org|), |org| + reach, |org| + reach and
// |plane| + |org| + pad, times |inv_dir|; the translation adds u |org| |inv_dir| (a rounded difference), and the
// planes, rounded outwards, only grow the boxes: under 5 u R |inv_dir| in all (first order, reach being 8 u R),
// less than pad, so a box the ray touches is never culled, at any coordinates. Ize's
// relative padding needs the difference plane - org, a subtraction and a multiplication per slab: this costs one
// FMA, as the fast mode does. The price: boxes widen by 8 u R in world units, a few float spacings of the
// tree's extent.
// A component under kMinSlabDir (a zero, say) is taken as kMinSlabDir: that only shrinks the axis's distances,
// which lowers near ones (conservative), and its far distances stay above pad >= 2^-21 2^64 R, past every point
// of the scene (within R of the origin on every axis) for a ray whose largest component exceeds 2^-40. An axis
// whose addends overflow (an origin or a pad beyond float range: |org| above about 1.8e19) or are NaN (a NaN
// direction) is disabled, never culling: inv_dir 0 and addends -inf and +inf give every box (-inf, +inf) on it.
// So a slab distance is never NaN but an empty slot's inf * 0 on a disabled axis, which culls that slot.
template <int N>
struct SlabRay {
    Vec3 inv_dir, near_add, far_add;
    int near[3], far[3];

    SlabRay() = default;  // for arrays of rays set up later (stream traversal)
    // In SSE lanes x, y, z: one division for the three reciprocals, no branches but one never taken. A frame's ray
    // waits on the hit before it, so this setup's latency is paid on every bounce: everything that does not need
    // the reciprocals (the planes' offsets from the direction's signs, the padded origin) is computed beside the
    // division, and the unusable axes' fix-up (see above) leaves the path behind a branch
    // (docs/results.md#a-rays-set-up-and-the-stacks-prefetches).
    [[gnu::always_inline]] SlabRay(const Ray& ray, const PlaneFrame& frame, bool robust) {
        const __m128 sign = _mm_set1_ps(-0.0f);
        const __m128 dir = _mm_setr_ps(ray.dir.x, ray.dir.y, ray.dir.z, 1.0f);
        const __m128 org = _mm_sub_ps(_mm_setr_ps(ray.org.x, ray.org.y, ray.org.z, 0.0f),
                                      _mm_setr_ps(frame.origin.x, frame.origin.y, frame.origin.z, 0.0f));
        const int negative = _mm_movemask_ps(dir);  // inv_dir's signs, a NaN's included (division keeps them)
        for (int a = 0; a < 3; ++a) {
            const int flip = (negative >> a & 1) * 3 * N;
            near[a] = flip + a * N;
            far[a] = 3 * N - flip + a * N;
        }
        // |dir| raised to kMinSlabDir with dir's sign; a NaN stays NaN (max returns its second operand then).
        const __m128 magnitude = _mm_max_ps(_mm_set1_ps(kMinSlabDir), _mm_andnot_ps(sign, dir));
        const __m128 safe_dir = _mm_or_ps(magnitude, _mm_and_ps(sign, dir));
        const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), safe_dir);
        // The padded addends as one product each: -(org + pad_org) inv with pad_org = reach sgn(dir), so that
        // -pad_org inv = -reach |inv_dir| = -pad on the near side and +pad on the far one.
        __m128 pad_org = _mm_setzero_ps();
        if (robust) {
            const __m128 abs_org = _mm_andnot_ps(sign, org);
            const __m128 yz = _mm_max_ps(_mm_movehdup_ps(abs_org), _mm_movehl_ps(abs_org, abs_org));
            const __m128 org_max = _mm_max_ps(abs_org, yz);  // lane 0: the largest |org| component
            const __m128 r = _mm_add_ps(_mm_set1_ps(frame.bound), _mm_broadcastss_ps(org_max));
            pad_org = _mm_or_ps(_mm_mul_ps(_mm_set1_ps(kRobustPad), r), _mm_and_ps(sign, dir));
        }
        // Fast mode multiplies org itself: org + 0 would turn an origin's -0 into +0 and flip a zero addend's sign.
        __m128 lower = _mm_xor_ps(_mm_mul_ps(robust ? _mm_add_ps(org, pad_org) : org, inv), sign);
        __m128 upper = _mm_xor_ps(_mm_mul_ps(robust ? _mm_sub_ps(org, pad_org) : org, inv), sign);
        __m128 inv_used = inv;
        const __m128 largest = _mm_set1_ps(std::numeric_limits<float>::max());
        const __m128 usable = _mm_and_ps(_mm_cmple_ps(_mm_andnot_ps(sign, lower), largest),
                                         _mm_cmple_ps(_mm_andnot_ps(sign, upper), largest));  // false on inf, NaN
        if (_mm_movemask_ps(usable) != 0xf) [[unlikely]] {
            const __m128 infinity = _mm_set1_ps(std::numeric_limits<float>::infinity());
            inv_used = _mm_and_ps(inv, usable);
            lower = _mm_blendv_ps(_mm_xor_ps(infinity, sign), lower, usable);
            upper = _mm_blendv_ps(infinity, upper, usable);
        }
        alignas(16) float lanes[3][4];
        _mm_store_ps(lanes[0], inv_used);
        _mm_store_ps(lanes[1], lower);
        _mm_store_ps(lanes[2], upper);
        for (int a = 0; a < 3; ++a) inv_dir[a] = lanes[0][a], near_add[a] = lanes[1][a], far_add[a] = lanes[2][a];
    }
};

// The SIMD form of a SlabRay: every per-ray value broadcast once, so the node test is loads and arithmetic.
template <int N>
struct SlabLanes {
    using S = simd::Simd<N>;
    typename S::F inv[3], near_add[3], far_add[3];
    int near[3], far[3];

    [[gnu::always_inline]] explicit SlabLanes(const SlabRay<N>& r) {
        for (int a = 0; a < 3; ++a) {
            inv[a] = S::set1(r.inv_dir[a]), near_add[a] = S::set1(r.near_add[a]), far_add[a] = S::set1(r.far_add[a]);
            near[a] = r.near[a], far[a] = r.far[a];
        }
    }
};

// A slab distance's bits as a signed integer. Slab distances are compared by these (Embree's trick): integer max and
// min take one cycle where the float ones take four, and they sit on every node's critical path (load, slab distances,
// interval, mask, child, next node; docs/results.md#traversal-kernels). Integer order is float order for +0 up to +inf;
// a negative float (-0 too) reads as a negative integer, below all of those. The near distances meet tmin >= +0
// (kernel_tmin), so their maximum is the float maximum; the far ones meet tmax, and their minimum is the float minimum
// unless one of them is negative, when it reads negative and the box, behind the origin, is culled. The one NaN a
// SlabRay leaves, an empty slot's, is x86's default NaN, negative: as a far distance it culls that slot.
[[gnu::always_inline]] inline int32_t distance_bits(float t) { return std::bit_cast<int32_t>(t); }

// Slab test of every child box against [tmin, tmax]; returns a bit mask of the children hit and their entry
// distances. The SIMD form below computes the same values, integer maxima and minima in any order being equal.
template <int N>
[[gnu::always_inline]] inline uint32_t intersect_children(const WideNode<N>& node, const SlabRay<N>& r, float tmin,
                                                          float tmax, std::array<float, N>& tnear) {
    const float* planes = node.planes;
    uint32_t mask = 0;
    for (int i = 0; i < N; ++i) {
        int32_t t0 = distance_bits(tmin), t1 = distance_bits(tmax);
        for (int a = 0; a < 3; ++a) {
            t0 = std::max(t0, distance_bits(std::fma(planes[r.near[a] + i], r.inv_dir[a], r.near_add[a])));
            t1 = std::min(t1, distance_bits(std::fma(planes[r.far[a] + i], r.inv_dir[a], r.far_add[a])));
        }
        tnear[i] = std::bit_cast<float>(t0);
        mask |= uint32_t(t0 <= t1) << i;
    }
    return mask;
}

// The interval test of N SIMD lanes over the slab distances x (near) and y (far) of each axis. The three axes are
// combined as a tree seeded with tmin and tmax, not a chain, which shortens each node's critical path.
template <int N>
[[gnu::always_inline]] inline uint32_t slab_mask(const typename simd::Simd<N>::F (&x)[3], const typename simd::Simd<N>::F (&y)[3],
                                                 typename simd::Simd<N>::F tmin, float tmax, std::array<float, N>& tnear) {
    using S = simd::Simd<N>;
    using F = typename S::F;
    const F t_max = S::set1(tmax);
    const F t0 = S::max_bits(S::max_bits(x[1], tmin), S::max_bits(x[2], S::max_bits(x[0], tmin)));
    const F t1 = S::min_bits(S::min_bits(y[1], t_max), S::min_bits(y[2], S::min_bits(y[0], t_max)));
    S::store(tnear.data(), t0);
    return S::le_mask_bits(t0, t1);
}

// The same for N SIMD lanes.
template <int N>
[[gnu::always_inline]] inline uint32_t intersect_children(const WideNode<N>& node, const SlabLanes<N>& r,
                                                          typename simd::Simd<N>::F tmin, float tmax,
                                                          std::array<float, N>& tnear) {
    using S = simd::Simd<N>;
    typename S::F x[3], y[3];  // near and far distances per axis
    for (int a = 0; a < 3; ++a) {
        x[a] = S::fmadd(S::load(node.planes + r.near[a]), r.inv[a], r.near_add[a]);
        y[a] = S::fmadd(S::load(node.planes + r.far[a]), r.inv[a], r.far_add[a]);
    }
    return slab_mask<N>(x, y, tmin, tmax, tnear);
}

// The same for a compressed node: each plane decoded by an FMA that rounds nothing (compressed_wide_bvh.h), then
// the same slab distances. The planes' bytes sit where WideNode's floats do, so the ray's offsets serve both.
template <int N>
[[gnu::always_inline]] inline uint32_t intersect_children(const CompressedNode<N>& node, const SlabLanes<N>& r,
                                                          typename simd::Simd<N>::F tmin, float tmax,
                                                          std::array<float, N>& tnear) {
    using S = simd::Simd<N>;
    typename S::F x[3], y[3];
    for (int a = 0; a < 3; ++a) {
        const auto scale = S::set1(node.scale[a]), origin = S::set1(node.origin[a]);
        x[a] = S::fmadd(S::fmadd(S::load_bytes(node.q + r.near[a]), scale, origin), r.inv[a], r.near_add[a]);
        y[a] = S::fmadd(S::fmadd(S::load_bytes(node.q + r.far[a]), scale, origin), r.inv[a], r.far_add[a]);
    }
    return slab_mask<N>(x, y, tmin, tmax, tnear) & node.valid;
}

// The lowest set bit's index, unsigned: as std::countr_zero's int, GCC widened the mask and then the index before
// addressing the node's arrays with it, two instructions on the way from a node's test to its child's loads.
[[gnu::always_inline]] inline size_t lowest_lane(uint32_t mask) { return size_t(unsigned(__builtin_ctz(mask))); }

struct StackEntry {
    uint32_t child, count;  // as in WideNode: count 0 is an inner node
    float tnear;
};

// Prefetches every cache line of a node (one for BVH2, two for BVH4 and compressed BVH8, four for BVH8), or a
// leaf's first lines.
template <class Node, class Leaf>
[[gnu::always_inline]] inline void prefetch(const Node* nodes, const Leaf* leaves, const StackEntry& e) {
    const char* p = e.count == 0 ? reinterpret_cast<const char*>(nodes + e.child) : reinterpret_cast<const char*>(leaves + e.child);
    for (size_t line = 0; line < sizeof(Node); line += 64) _mm_prefetch(p + line, _MM_HINT_T0);
}

// Starts the fetch of a node's child references with that of its boxes, where they lie on a cache line of their
// own (BVH8: boxes on lines 0 to 2, references on line 3). Otherwise that line is requested only once the slab
// test has chosen a child, a second miss on every node's critical path (docs/results.md#traversal-kernels).
template <int N>
[[gnu::always_inline]] inline void prefetch_child_line(const WideNode<N>& node) {
    if constexpr (sizeof(node.planes) % 64 == 0) _mm_prefetch(reinterpret_cast<const char*>(node.child), _MM_HINT_T0);
}
// A compressed BVH8 node's second line holds its last planes and its child references.
template <int N>
[[gnu::always_inline]] inline void prefetch_child_line(const CompressedNode<N>& node) {
    _mm_prefetch(reinterpret_cast<const char*>(&node) + 64, _MM_HINT_T0);
}

// Intersects a leaf's triangles; true when a hit was recorded.
template <class Tree, class TriangleTest, class Counter>
[[gnu::always_inline]] inline bool intersect_leaf(const Tree& bvh, const StackEntry& leaf,
                                                  const TriangleTest& tri_ray, float tmin, Hit& hit, Counter& counter) {
    constexpr int N = Tree::kWidth;
    counter.leaf();
    counter.triangles(leaf.count);
    counter.touch(&bvh.leaves[leaf.child], sizeof(bvh.leaves[0]) * (N == 2 ? leaf.count : leaf_entries(N, leaf.count)));
    bool found = false;
    if constexpr (N == 2) {
        for (uint32_t i = leaf.child; i < leaf.child + leaf.count; ++i) {
            const LeafTriangle& t = bvh.leaves[i];
            if (tri_ray.intersect(t.v0, t.v1, t.v2, t.prim, tmin, hit)) found = true, counter.nearer_hit(t, 0);
        }
    } else {
        const uint32_t end = leaf.child + leaf_entries(N, leaf.count);
        for (uint32_t b = leaf.child; b < end; ++b) {
            const int lane = tri_ray.intersect_block(bvh.leaves[b], tmin, hit);
            if (lane >= 0) found = true, counter.nearer_hit(bvh.leaves[b], lane);
        }
    }
    return found;
}

// A triangle test set up on first use, constructed in place: std::optional's emplace left GCC an out-of-line
// std::_Construct call for it, visible in a frame's profile (docs/results.md#traversal-kernels).
template <class TriangleTest>
class LazyTest {
    static_assert(std::is_trivially_destructible_v<TriangleTest>);

public:
    LazyTest() {}
    [[gnu::always_inline]] void set(const Ray& ray) {
        new (&test_) TriangleTest(ray);
        ready_ = true;
    }
    [[gnu::always_inline]] const TriangleTest& get(const Ray& ray) {
        if (!ready_) set(ray);
        return test_;
    }

private:
    union {
        TriangleTest test_;
    };
    bool ready_ = false;
};

// The per-ray form the node test of width N takes: SlabRay itself for the scalar BVH2 test, else SlabLanes.
template <int N>
using NodeRay = std::conditional_t<N == 2, SlabRay<N>, SlabLanes<N>>;

// The traversal loop of every kernel: from `start` (the root, or any node or leaf of a tree, as the two-level
// kernels enter object trees), children near to far, leaves handed to `leaf(entry)`, which returns true when it
// recorded a hit. `hit.t` is the running far limit, held in a local between hits. Tree is anything with `nodes`
// (WideNode<N> or CompressedNode<N>) and `leaves`. Returns true when an any-hit query may stop.
template <Query Q, int N, class Tree, class Counter, class LeafFn>
[[gnu::always_inline]] inline bool traverse_from(const Tree& tree, StackEntry start, const SlabRay<N>& box_ray,
                                                 float tmin, Hit& hit, Counter& counter, LeafFn&& leaf) {
    // Locals the loop's stores cannot alias, so the compiler keeps them in registers (a node's address is then one
    // multiply-add away, not two dependent loads through `tree`).
    const auto* const nodes = tree.nodes.data();
    const auto* const leaves = tree.leaves.data();
    const NodeRay<N> ray(box_ray);
    const auto t_min = [&] {
        if constexpr (N == 2) return tmin;
        else return simd::Simd<N>::set1(tmin);
    }();
    float tfar = hit.t;
    StackEntry stack[kMaxBvhDepth * (N - 1) + 1];
    StackEntry* sp = stack;
    StackEntry current = start;
    for (;;) {
        if (current.count == 0) {
            counter.inner();
            const auto& node = nodes[current.child];
            counter.touch(&node, sizeof(node));
            prefetch_child_line(node);
            std::array<float, N> tnear;
            uint32_t mask = intersect_children<N>(node, ray, t_min, tfar, tnear);
            // The counts through a pointer the compiler cannot relate to the child references: else GCC adds the
            // references' offset to the lane index, to share one address for both loads, an add on the way from
            // the node's test to its child's loads, measurable in the traversal alone
            // (docs/results.md#the-node-steps-instructions-and-variants-measured-on-one-thread).
            const auto* counts = node.count;
            asm("" : "+r"(counts));

            if (mask) {
                const size_t a = lowest_lane(mask);
                mask &= mask - 1;
                if (!mask) {  // one child hit: go there directly
                    current = {node.child[a], counts[a], tnear[a]};
                    continue;
                }
                // Any hit needs a hit, not the nearest: no sorting by distance, and the children in the tree's
                // order, leaves first, each a chance to end the ray before another node's fetch
                // (docs/results.md#any-hit-on-random-rays).
                if constexpr (Q == Query::Any) {
                    const uint32_t hit_lanes = uint32_t(mask) | (1u << a);
                    uint32_t leaf_lanes = 0;
                    for (uint32_t m = hit_lanes; m; m &= m - 1) leaf_lanes |= uint32_t(counts[lowest_lane(m)] != 0) << lowest_lane(m);
                    const size_t first = leaf_lanes ? lowest_lane(leaf_lanes) : a;
                    const uint32_t rest = hit_lanes & ~(1u << first);
                    // Inner nodes pushed first, so that the leaves above them are popped first.
                    for (const uint32_t group : {rest & ~leaf_lanes, rest & leaf_lanes})
                        for (uint32_t m = group; m; m &= m - 1) {
                            const size_t i = lowest_lane(m);
                            *sp++ = {node.child[i], counts[i], tnear[i]};
                        }
                    current = {node.child[first], counts[first], tnear[first]};
                    continue;
                }
                const size_t b = lowest_lane(mask);
                mask &= mask - 1;
                if (!mask) {  // two: go to the nearer, keep the farther
                    const size_t near = tnear[b] < tnear[a] ? b : a, far = near == a ? b : a;
                    *sp = {node.child[far], counts[far], tnear[far]};
                    prefetch(nodes, leaves, *sp++);  // its fetch overlaps the near subtree's work
                    current = {node.child[near], counts[near], tnear[near]};
                    continue;
                }
                // More: push all hit children far to near by insertion into the stack top, then take the nearest.
                // Forced inline, as the leaf lambdas the kernels pass: GCC had made both calls in some kernels.
                StackEntry* const base = sp;
                const auto push = [&](size_t i) __attribute__((always_inline)) {
                    const StackEntry e{node.child[i], counts[i], tnear[i]};
                    StackEntry* j = sp++;
                    for (; j > base && j[-1].tnear < e.tnear; --j) *j = j[-1];
                    *j = e;
                };
                push(a);
                push(b);
                for (; mask; mask &= mask - 1) push(lowest_lane(mask));
                current = *--sp;
                // Only the two children popped next are prefetched (three or more were hit, so both are this
                // node's): every pushed child's four lines crowded the load queue with lines a nearer hit often
                // culls, and the second child's prefetch still made the traversal alone a little faster
                // (docs/results.md#a-rays-set-up-and-the-stacks-prefetches).
                prefetch(nodes, leaves, sp[-1]);
                prefetch(nodes, leaves, sp[-2]);
                continue;
            }
        } else if (leaf(current)) {
            if constexpr (Q == Query::Any) return true;
            tfar = hit.t;
        }
        do {
            if (sp == stack) return false;
            current = *--sp;
        } while (current.tnear > tfar);
    }
}

// The whole walk of one tree of `pool` from the node `root`, the ray's triangles tested in the world's (or the
// tree's) space: the flat kernel's body, and the two-level kernel's where no instance needs a ray of its own.
template <Query Q, bool Robust, class TriangleTest, int N, class Tree, class Counter>
[[gnu::always_inline]] inline void traverse_tree(const Tree& pool, uint32_t root, const BBox& bounds,
                                                 const PlaneFrame& frame, const Ray& ray, Hit& hit, Counter& counter) {
    const SlabRay<N> box_ray(ray, frame, Robust);
    const float tmin = kernel_tmin(ray);
    // The triangle test is set up at once for a ray that starts inside the scene's box, since such a ray nearly
    // always reaches a leaf and the setup then overlaps the first nodes' work; else at the first leaf, since many
    // rays from outside reach none: setting up always sped up rooms and slowed objects seen from outside, the gate
    // keeps the first without the second (docs/results.md#traversal-kernels).
    LazyTest<TriangleTest> tri_ray;
    if (bounds.contains(ray.org)) tri_ray.set(ray);
    const auto leaf = [&](const StackEntry& entry) __attribute__((always_inline)) {
        return intersect_leaf(pool, entry, tri_ray.get(ray), tmin, hit, counter);
    };
    traverse_from<Q>(pool, {root, 0, tmin}, box_ray, tmin, hit, counter, leaf);
}

// A flat tree's walk from its root, `hit` reset to the ray's interval.
template <Query Q, bool Robust, class TriangleTest, int N, class Tree, class Counter>
[[gnu::always_inline]] inline bool traverse_flat(const Tree& bvh, const Ray& ray, Hit& hit, Counter& counter) {
    hit = Hit{};
    hit.t = ray.tmax;
    if (bvh.nodes.empty()) return false;
    traverse_tree<Q, Robust, TriangleTest, N>(bvh, 0, bvh.bounds, bvh.frame, ray, hit, counter);
    return hit.found();
}

}  // namespace detail

// Closest hit (Query::Closest) or any hit (Query::Any) in (kernel_tmin(ray), ray.tmax]. For Any, `hit` holds the
// first hit found, not the closest. One out-of-line function per kernel with every piece of the loop forced
// inline: in the renderer's translation unit, which instantiates every width, mode and top level, GCC had left
// the node test a call per node reading the ray through memory (docs/results.md#traversal-kernels). Inlining the
// whole traversal into the path tracer measured slower.
template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
[[gnu::noinline]] bool traverse(const WideBvh<N>& bvh, const Ray& ray, Hit& hit, Counter&& counter = {}) {
    return detail::traverse_flat<Q, Robust, TriangleTest, N>(bvh, ray, hit, counter);
}
template <Query Q, bool Robust = true, class TriangleTest = WatertightRay, int N, class Counter = NoCount>
[[gnu::noinline]] bool traverse(const CompressedWideBvh<N>& bvh, const Ray& ray, Hit& hit, Counter&& counter = {}) {
    return detail::traverse_flat<Q, Robust, TriangleTest, N>(bvh, ray, hit, counter);
}

template <bool Robust = true, class TriangleTest = WatertightRay, class Tree>
bool closest_hit(const Tree& bvh, const Ray& ray, Hit& hit)
    requires std::is_same_v<Tree, WideBvh<Tree::kWidth>> || std::is_same_v<Tree, CompressedWideBvh<Tree::kWidth>>
{
    return traverse<Query::Closest, Robust, TriangleTest>(bvh, ray, hit);
}

template <bool Robust = true, class TriangleTest = WatertightRay, class Tree>
bool any_hit(const Tree& bvh, const Ray& ray)
    requires std::is_same_v<Tree, WideBvh<Tree::kWidth>> || std::is_same_v<Tree, CompressedWideBvh<Tree::kWidth>>
{
    Hit hit;
    return traverse<Query::Any, Robust, TriangleTest>(bvh, ray, hit);
}

}  // namespace canopy
