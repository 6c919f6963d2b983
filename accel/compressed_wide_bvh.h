#pragma once
// A wide BVH whose nodes hold their children's boxes quantised to 8 bits per plane, relative to the node's own box
// (Ylitie, Karras and Laine 2017, sec. 3.2, on GPUs; Benthin et al. 2018 on CPUs): a BVH8 node in 128 bytes, two
// cache lines, instead of 256. Made from a collapsed WideBvh; the leaves are the same blocks.
//
// Conservative and exact: per node and axis the planes are origin + q 2^e for bytes q, the origin a multiple of
// 2^e and e large enough that every such value is a float (see quantise_axis), lower planes rounded down and
// upper ones up. A kernel decodes a plane with one FMA that does not round, so no box shrinks, and then runs the
// slab test of the uncompressed kernel on it: robust traversal keeps its guarantee, and the closest hit's distance
// is the uncompressed tree's, bit for bit. Boxes a step larger change the order of visits, so where triangles tie
// at that distance (a ray through a shared edge) the other triangle may be the one reported.
#include "accel/wide_bvh.h"

#include <cstdint>

namespace canopy {

template <int N>
struct alignas(64) CompressedNode {
    float origin[3];  // in the tree's PlaneFrame
    float scale[3];   // powers of two
    // Per child i and axis a, as WideNode::planes: lower plane at q[a * N + i], upper at q[(3 + a) * N + i].
    uint8_t q[6 * N];
    uint8_t valid;       // bit i: slot i holds a child (empty slots' bytes decode to an inverted box)
    uint16_t count[N];   // as WideNode::count
    uint32_t child[N];   // as WideNode::child

    float lower(int axis, int i) const { return origin[axis] + float(q[axis * N + i]) * scale[axis]; }
    float upper(int axis, int i) const { return origin[axis] + float(q[(3 + axis) * N + i]) * scale[axis]; }
    bool is_empty(int i) const { return !(valid >> i & 1); }
};
static_assert(sizeof(CompressedNode<8>) == 128);

template <int N>
struct CompressedWideBvh {
    static constexpr int kWidth = N;
    using Leaf = LeafOf<N>;
    std::vector<CompressedNode<N>, HugePageAllocator<CompressedNode<N>>> nodes;  // nodes[0] is the root
    std::vector<Leaf, HugePageAllocator<Leaf>> leaves;
    BBox bounds;
    PlaneFrame frame;  // its bound covers the decoded planes, which reach a quantum beyond the exact ones

    uint64_t bytes() const { return nodes.size() * sizeof(CompressedNode<N>) + leaves.size() * sizeof(Leaf); }
};

// One axis of a node: planes origin + q 2^exponent (q in 0..255) with lower planes at or below `lower` and
// upper ones at or above `upper`. Exposed for tests.
struct QuantisedAxis {
    float origin, scale;
    int exponent;
    double first_step;  // origin / scale, an integer below 2^24 in magnitude
    uint8_t quantise_lower(float x) const;
    uint8_t quantise_upper(float x) const;
};
// The axis of the node box [lower, upper] (finite, lower <= upper).
QuantisedAxis quantise_axis(float lower, float upper);

// The node with its children's boxes quantised; throws std::length_error for a leaf of more than 65,535 triangles.
template <int N>
CompressedNode<N> compress_node(const WideNode<N>& node);

// The compressed tree (the leaves move over), and back: the decoded boxes in uncompressed nodes, for metrics.
template <int N>
CompressedWideBvh<N> compress(WideBvh<N>&& bvh);
template <int N>
WideBvh<N> decompress(const CompressedWideBvh<N>& bvh);

// The layouts a wide tree is stored in: "standard" (WideNode) or "compressed" (CompressedNode, bvh8 only).
enum class NodeLayout { Standard, Compressed };
// Throws std::invalid_argument naming the known layouts.
NodeLayout parse_node_layout(const std::string& name);

}  // namespace canopy
