#pragma once
// Traversal layout: N-wide nodes holding their children's boxes in SoA, collapsed from any builder's
// binary BVH, with leaf triangles copied in leaf order so a leaf is one contiguous run.
#include "accel/bvh.h"
#include "accel/huge_page_allocator.h"

#include <span>

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
    bool is_leaf(int i) const { return count[i] != 0; }
    bool is_empty(int i) const { return child[i] == kEmpty; }
};
static_assert(sizeof(WideNode<2>) == 64);

// A triangle as the intersector wants it, with the id of the scene triangle it came from.
struct LeafTriangle {
    Vec3 v0;
    uint32_t prim;
    Vec3 v1, v2;
};

template <int N>
struct WideBvh {
    std::vector<WideNode<N>, HugePageAllocator<WideNode<N>>> nodes;  // nodes[0] is the root, never a leaf
    std::vector<LeafTriangle, HugePageAllocator<LeafTriangle>> triangles;
    BBox bounds;

    uint64_t bytes() const { return nodes.size() * sizeof(WideNode<N>) + triangles.size() * sizeof(LeafTriangle); }
};

// SAH-driven collapse (Ganestam and Doggett 2016, sec. 4.2): a node's children are its binary
// children, then repeatedly the inner child with the largest surface area is replaced by its two
// children until there are N. A root that is a leaf becomes a node with one leaf child.
template <int N>
WideBvh<N> collapse(const Bvh& bvh, std::span<const Triangle> triangles);

}  // namespace canopy
