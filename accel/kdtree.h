#pragma once
// The SAH kd-tree of Wald and Havran 2006, "On building fast kd-trees for ray tracing, and on doing that in
// O(N log N)": events sorted once and swept and spliced in linear time per node (its O(N log N) algorithm), "perfect
// splits" (every straddling triangle clipped exactly to each child's voxel, so its candidate planes come from the
// clipped bounds), the SAH with the empty-space bonus lambda(p), and termination by cost and depth. Subtrees are
// built in parallel. A second structure family beside the BVH: engine/kd_accelerator.cpp traces it. Leaves are stored
// as the wide BVHs store theirs, in SIMD triangle blocks (accel/wide_bvh.h), so the kernel tests them with the same
// block tests.
#include "base/geometry.h"
#include "accel/wide_bvh.h"

#include <cstdint>
#include <span>
#include <vector>

namespace canopy {

// The --builder name of the kd-tree (the registry lists it among the structure families).
inline constexpr const char* kKdTreeName = "kdtree";

// The constants of the cost model and of termination, all in one place.
struct KdSettings {
    float traversal = 15.0f;     // K_T: one inner node's traversal step (the paper's 15)
    float intersection = 20.0f;  // K_I: one triangle test (the paper's 20)
    float empty_bonus = 0.8f;    // lambda(p): a split that cuts off empty space costs 80%
    // Depth limit 8 + 1.3 log2 N (Havran's thesis), never beyond kKdMaxDepth.
    float depth_base = 8.0f, depth_per_log2 = 1.3f;
    // References in leaves at most this many per triangle: a node whose split would exceed its share becomes a
    // leaf, so thousands of huge overlapping triangles cannot grow the tree without bound.
    double max_references_per_triangle = 8.0;
};

// Every kd-tree is at most this deep (edges from the root), so traversal stacks have a fixed size.
constexpr uint32_t kKdMaxDepth = 60;

// 8 bytes. Inner: the split plane's position and axis (0 to 2), the below child next in the array and the above
// child at `above`. Leaf: axis bits 3, `count` triangles in kd_blocks(count) blocks from `first` in
// KdTree::leaf_blocks.
struct KdNode {
    uint32_t bits;  // low 2 bits: axis, or 3 for a leaf; the rest: inner, the above child; leaf, the count
    union {
        float split;
        uint32_t first;
    };

    bool is_leaf() const { return (bits & 3u) == 3u; }
    int axis() const { return int(bits & 3u); }
    uint32_t above() const { return bits >> 2; }
    uint32_t count() const { return bits >> 2; }
};
static_assert(sizeof(KdNode) == 8);

// A leaf's triangles, a lane each in order, in blocks of the lanes the wide BVH kernels test at once on this build
// (block_lanes); the last block's spare lanes hold TriangleBlock's padding (prim kNone, never hit). Blocks pay where
// leaves hold many triangles (long slivers) and cost memory where they hold one or two; 8 lanes take more memory than
// 4 but traced slivers faster (docs/results.md#kd-leaves-as-simd-blocks, docs/results.md#builds-and-layouts).
constexpr int kKdLanes = block_lanes(8);
using KdBlock = TriangleBlock<kKdLanes>;

constexpr uint32_t kd_blocks(uint32_t count) { return (count + kKdLanes - 1) / kKdLanes; }

struct KdTree {
    std::vector<KdNode> nodes;  // nodes[0] is the root
    std::vector<KdBlock> leaf_blocks;
    BBox bounds;  // the root's voxel: the scene's bounds
    uint32_t depth = 0;

    // The memory the tree occupies, padding lanes included.
    uint64_t bytes() const { return nodes.size() * sizeof(KdNode) + leaf_blocks.size() * sizeof(KdBlock); }
};

// Throws std::invalid_argument for settings outside their domain (negative costs, a bonus outside (0, 1]).
KdTree build_kdtree(std::span<const Triangle> triangles, const KdSettings& settings = {});

struct KdStats {
    uint64_t nodes = 0, leaves = 0, depth = 0;
    uint64_t references = 0;  // the leaves' triangles, padding lanes not counted
    double refs_per_triangle = 0;
};
KdStats kd_stats(const KdTree& tree, uint64_t triangles);

// Eq. 1 of the quality-metrics paper applied to the kd-tree, each node's area that of its voxel (the box its
// splits cut from the scene's bounds), not of its triangles' bounds: (C_inn sum_I A_n + C_tri sum_L T_n A_n) /
// A_root, with the BVH's C_inn = 1.2 and C_tri = 1 so that the figure compares with the BVH rows'.
double kd_sah_cost(const KdTree& tree, float inner = 1.2f, float triangle = 1.0f);

}  // namespace canopy
