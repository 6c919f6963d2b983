#pragma once
// Traversal layout: N-wide nodes holding their children's boxes in SoA, collapsed from any builder's
// binary BVH, with leaf triangles copied in leaf order so a leaf is one contiguous run (N = 2) or one
// run of N-wide SoA blocks (N = 4, 8).
#include "accel/bvh.h"
#include "base/huge_pages.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <type_traits>

namespace canopy {

template <int N>
struct alignas(64) WideNode {
    static constexpr uint32_t kEmpty = 0xffffffffu;
    // Per child i and axis a: lower bound at planes[a * N + i], upper at planes[(3 + a) * N + i], so a
    // kernel reaches the near or far plane of an axis by one offset chosen per ray. Empty slots hold an
    // inverted box (never hit).
    float planes[6 * N];
    uint32_t child[N];  // inner child: node index; leaf child: first leaf triangle; empty: kEmpty
    uint32_t count[N];  // leaf child: triangle count; inner child or empty: 0

    float& lower(int axis, int i) { return planes[axis * N + i]; }
    float& upper(int axis, int i) { return planes[(3 + axis) * N + i]; }
    float lower(int axis, int i) const { return planes[axis * N + i]; }
    float upper(int axis, int i) const { return planes[(3 + axis) * N + i]; }
    bool is_leaf(int i) const { return count[i] != 0; }
    bool is_empty(int i) const { return child[i] == kEmpty; }
};
static_assert(sizeof(WideNode<2>) == 64 && sizeof(WideNode<4>) == 128 && sizeof(WideNode<8>) == 256);

// x - origin rounded towards -inf (upwards = false) or +inf: the float difference corrected by its exact rounding
// error (Knuth's TwoSum). Infinities, an empty slot's planes, stay infinite.
inline float difference_rounded(float x, float origin, bool upwards) {
    const float s = x - origin;
    if (!std::isfinite(s)) return s;
    const float back = s - x;
    const float error = (x - (s - back)) + (-origin - back);
    if (upwards ? error > 0.0f : error < 0.0f)
        return std::nextafter(s, upwards ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity());
    return s;
}

// The coordinates a tree's planes are stored in: relative to `origin`, a point near the tree's geometry, rounded
// outwards, so that robust traversal's padding, which grows with the magnitude of the coordinates in the slab test
// (see SlabRay, kernels/traverse.h), grows with the tree's extent, not its distance from the coordinate origin.
// The kernels translate the ray's origin, never its distances; the triangle tests keep world coordinates.
// `bound` bounds the magnitude of every plane stored in this frame. Planes are read and written only here.
struct PlaneFrame {
    Vec3 origin{0.0f};
    float bound = 0.0f;

    // The frame at `origin` for boxes inside `box`.
    static PlaneFrame at(const Vec3& origin, const BBox& box) {
        PlaneFrame frame{origin, 0.0f};
        if (box.empty()) return frame;
        const BBox relative = frame.relative(box);
        for (int a = 0; a < 3; ++a)
            frame.bound = std::max({frame.bound, std::abs(relative.lower[a]), std::abs(relative.upper[a])});
        return frame;
    }
    // The frame at the centre of `box`.
    static PlaneFrame centred(const BBox& box) {
        return at(box.empty() ? Vec3(0.0f) : 0.5f * box.lower + 0.5f * box.upper, box);
    }

    // `box` in this frame, rounded outwards: it contains the exact translated box.
    BBox relative(const BBox& box) const {
        BBox out;
        for (int a = 0; a < 3; ++a) {
            out.lower[a] = difference_rounded(box.lower[a], origin[a], false);
            out.upper[a] = difference_rounded(box.upper[a], origin[a], true);
        }
        return out;
    }
    template <int N>
    void set_box(WideNode<N>& node, int i, const BBox& box) const {
        const BBox r = relative(box);
        for (int a = 0; a < 3; ++a) node.lower(a, i) = r.lower[a], node.upper(a, i) = r.upper[a];
    }
    // Child i's box in world coordinates; it contains the box set_box was given (rounding to nearest keeps the
    // order of the exact sums, which lie outside that box).
    template <int N>
    BBox box(const WideNode<N>& node, int i) const {
        BBox out;
        for (int a = 0; a < 3; ++a) out.lower[a] = origin[a] + node.lower(a, i), out.upper[a] = origin[a] + node.upper(a, i);
        return out;
    }
};

// A triangle as the intersector wants it, with the id of the scene triangle it came from.
struct LeafTriangle {
    Vec3 v0;
    uint32_t prim;
    Vec3 v1, v2;
};

// W triangles in SoA for the SIMD intersector: v[vertex][axis][lane]. Lanes holding no triangle hold a
// degenerate triangle at the origin (never hit) and prim kNone.
template <int W>
struct alignas(4 * W) TriangleBlock {
    static constexpr int kLanes = W;
    static constexpr uint32_t kNone = 0xffffffffu;
    float v[3][3][W];
    uint32_t prim[W];
};
static_assert(sizeof(TriangleBlock<4>) == 160 && sizeof(TriangleBlock<8>) == 320);

// Lanes of the leaf intersector: binary nodes test one LeafTriangle at a time with the scalar intersector;
// BVH4 and BVH8 test 8 triangles at once with AVX where the build has it, else 4 with SSE: 8-lane blocks traced
// faster than 4-lane ones with both widths, for somewhat more memory (docs/results.md#builds-and-layouts).
constexpr int block_lanes(int width) {
#if defined(__AVX2__)
    return width > 2 ? 8 : 1;
#else
    return width > 2 ? 4 : 1;
#endif
}

// A leaf child's `child` indexes `leaves`; its `count` is always the number of triangles. With blocks (N > 2) a
// leaf child is its leaf_entries(N, count) blocks from `child`, which the kernels test whole, every lane: the
// one-triangle leaves of one wide node share a block, a lane each in child order (the k-th such child has lane
// k), so a one-triangle leaf's block may hold its siblings' triangles too. Testing them with it costs no more (the lanes are tested anyway) and
// what they hit are real hits, so closest and any hits stay exact; an LBVH's one-triangle leaves take a block
// per wide node instead of one each.
template <int N>
using LeafOf = std::conditional_t<(N > 2), TriangleBlock<block_lanes(N)>, LeafTriangle>;

inline uint32_t leaf_entries(int width, uint32_t triangles) {
    const uint32_t lanes = uint32_t(block_lanes(width));
    return (triangles + lanes - 1) / lanes;
}

template <int N>
using WideNodes = std::vector<WideNode<N>, HugePageAllocator<WideNode<N>>>;

template <int N>
struct WideBvh {
    static constexpr int kWidth = N;
    using Leaf = LeafOf<N>;
    WideNodes<N> nodes;  // nodes[0] is the root, never a leaf
    std::vector<Leaf, HugePageAllocator<Leaf>> leaves;
    BBox bounds;
    PlaneFrame frame;  // the nodes' planes are stored in it

    uint64_t bytes() const { return nodes.size() * sizeof(WideNode<N>) + leaves.size() * sizeof(Leaf); }
};

// How collapse() chooses each wide node's children from the binary tree below it.
enum class CollapseMethod {
    // The least-cost wide tree (Ylitie, Karras and Laine 2017, sec. 3.1): which binary nodes become wide nodes,
    // which are opened into their parent's slots, and which subtrees of at most a block's triangles become one
    // leaf, by a dynamic program over the binary tree that charges node tests and block tests by surface area.
    Optimal,
    // SAH-driven greedy collapse (Ganestam and Doggett 2016, sec. 4.2): a node's children are its binary children,
    // then repeatedly the inner child with the largest surface area is replaced by its two children until there
    // are N.
    Greedy,
    // No collapse: lbvh's wide tree emitted straight from its sorted Morton codes (build_wide_lbvh,
    // accel/builders/lbvh_direct.h), for builder lbvh only. collapse() refuses it.
    Direct,
};

// "optimal", "greedy" or "direct"; otherwise throws std::invalid_argument naming the known methods.
CollapseMethod parse_collapse_method(const std::string& name);

// The wide tree of a binary one. A root that is a leaf becomes a node with one leaf child. Its planes are stored
// relative to `origin`, by default the centre of its box.
template <int N>
WideBvh<N> collapse(const Bvh& bvh, std::span<const Triangle> triangles, CollapseMethod method = CollapseMethod::Optimal,
                    std::optional<Vec3> origin = {});

// The same tree with nodes 1.. in a random order in memory, fixed by `seed`, and every inner child re-pointed:
// the node-order experiment of Aila, Karras and Laine 2013, sec. 6 (leaves stay where they are).
template <int N>
void permute_nodes(WideBvh<N>& tree, uint64_t seed);

// A leaf of a wide tree: its first entry in the tree's leaf array, and the binary leaf's refs it is made of.
struct LeafRun {
    uint32_t first_entry, first_ref, count;
};

// The node half of collapse, for trees whose leaves hold something else than triangles (the two-level top
// level): writes `nodes`, their planes in `frame`; a binary leaf of n refs takes entries(N, n) leaf entries,
// `total_entries` in all. Returns the leaves in emission order, for the caller to fill. The optimal method
// charges each leaf as a block test over its box, a stand-in for whatever lies below it: on a re-braided top level
// it cut a ray's inner node visits and cache lines against greedy's (docs/results.md#builds-and-layouts).
template <int N>
std::vector<LeafRun> collapse_nodes(const Bvh& bvh, WideNodes<N>& nodes, const PlaneFrame& frame,
                                    uint32_t (*entries)(int, uint32_t), uint32_t& total_entries, CollapseMethod method);

}  // namespace canopy
