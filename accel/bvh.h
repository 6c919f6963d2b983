#pragma once
// The binary BVH that every builder produces. Leaves index into `refs`, a list of triangle ids in
// which a triangle may appear more than once (split builders place pieces of it in several leaves).
#include "base/geometry.h"

#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace canopy {

struct BvhNode {
    BBox bounds;
    uint32_t index = 0;  // inner: left child (the right child is index + 1); leaf: first ref
    uint32_t count = 0;  // leaf: number of refs; 0 marks an inner node

    bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32);

// Allocates node arrays without initialising them: builders write every node they resize to, so value-initialising
// them first (empty boxes, zero counts) is a wasted pass over the array, a fast build's sizeable share
// (docs/results.md#builds-and-layouts). BvhNode is an aggregate, an implicit-lifetime type, so the allocated bytes
// are its objects as they are.
template <class T>
struct UninitializedAllocator : std::allocator<T> {
    static_assert(std::is_trivially_destructible_v<T> && std::is_trivially_copyable_v<T>);
    template <class U>
    struct rebind {
        using other = UninitializedAllocator<U>;
    };
    UninitializedAllocator() = default;
    template <class U>
    UninitializedAllocator(const UninitializedAllocator<U>&) {}
    template <class U>
    void construct(U*) noexcept {}  // default construction: the bytes stay as they are
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

using BvhNodes = std::vector<BvhNode, UninitializedAllocator<BvhNode>>;

// Every builder keeps its trees at most this deep (edges from the root), so traversal stacks have a
// fixed size. Past kMedianFallbackDepth a builder cuts at the median, which adds at most 32 levels.
constexpr uint32_t kMaxBvhDepth = 96;
constexpr uint32_t kMedianFallbackDepth = 64;

// What a split builder reports of its splitting, for the bench's split columns (Tables 3 and 4 of the
// split-partitioning paper, section 4.1's memory figure). Zero for builders that do not split.
struct SplitReport {
    double split_ms = 0;             // wall time of the split pass, inside the build time
    uint64_t reference_capacity = 0; // PrimRef slots allocated for references, against the refs in the tree
};

// A subtree's refs when they are consecutive in Bvh::refs: the first and how many.
struct SubtreeRefs {
    uint32_t first, count;
};

struct Bvh {
    BvhNodes nodes;  // nodes[0] is the root; resize() leaves the new nodes unwritten
    std::vector<uint32_t> refs;  // triangle ids, leaf by leaf
    // Optional, by node, from a builder that knows it for free and whose every leaf holds one ref, in refs' order
    // from left to right (LBVH): the node's subtree's refs. Empty otherwise. Code that rewrites such a builder's
    // tree (an optimiser, collapsing leaves) clears it.
    std::vector<SubtreeRefs> one_ref_leaves;
    SplitReport split;
};

// Constants of eq. 1 in Aila, Karras and Laine 2013.
struct SahCosts {
    float inner = 1.2f;     // C_inn
    float triangle = 1.0f;  // C_tri
};

// Eq. 1 of the quality-metrics paper: (C_inn sum_I A_n + C_tri sum_L T_n A_n) / A_root.
double sah_cost(const Bvh& bvh, SahCosts costs = {});

struct TreeStats {
    uint64_t nodes = 0;
    uint64_t inner_nodes = 0;
    uint64_t leaves = 0;
    uint32_t depth = 0;             // edges on the longest root-to-leaf path
    uint64_t references = 0;        // sum of leaf sizes
    double refs_per_triangle = 0;   // 1 without splits; 1.19 is 19% split increase
    uint64_t max_leaf_size = 0;
    uint64_t bytes = 0;             // nodes + refs as stored
};

TreeStats tree_stats(const Bvh& bvh, uint64_t triangle_count);

}  // namespace canopy
