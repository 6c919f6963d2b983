#include "accel/builders/bonsai.h"

#include "accel/parallel.h"
#include "accel/builders/split_partitioning.h"
#include "accel/builders/sweep_sah.h"

#include <bit>
#include <chrono>

namespace canopy {
namespace {

// Depth budget: mini-trees cut at the median from depth 32 (so at most 64 deep) and the top tree stays within 32
// levels, which keeps the assembled tree within kMaxBvhDepth.
constexpr uint32_t kMiniTreeMedianDepth = 32;
constexpr uint32_t kTopTreeMaxDepth = 32;
static_assert(kTopTreeMaxDepth + 2 * kMiniTreeMedianDepth <= kMaxBvhDepth);
// Bonsai's pruning: a mini-tree node whose box has more than this fraction of the scene's surface area is removed
// and its children are handed to the top tree instead, so that large triangles the mid-point partitioning put
// among small ones can be placed higher up.
constexpr float kPruneAreaFraction = 0.01f;

using Clock = std::chrono::steady_clock;

struct SubtreeRoot {
    uint32_t tree, node;
};

void prune(const Bvh& tree, uint32_t tree_index, uint32_t node, float max_half_area, std::vector<SubtreeRoot>& roots) {
    const BvhNode& n = tree.nodes[node];
    if (n.is_leaf() || n.bounds.half_area() <= max_half_area) {
        roots.push_back({tree_index, node});
        return;
    }
    prune(tree, tree_index, n.index, max_half_area, roots);
    prune(tree, tree_index, n.index + 1, max_half_area, roots);
}

// Copies the subtree at `node` of `from` into `slot` of `out`, children adjacent, refs appended leaf by leaf.
void copy_subtree(const Bvh& from, uint32_t node, uint32_t slot, Bvh& out) {
    const BvhNode& n = from.nodes[node];
    if (n.is_leaf()) {
        out.nodes[slot] = {n.bounds, uint32_t(out.refs.size()), n.count};
        out.refs.insert(out.refs.end(), from.refs.begin() + n.index, from.refs.begin() + n.index + n.count);
        return;
    }
    const uint32_t children = uint32_t(out.nodes.size());
    out.nodes.resize(children + 2);
    out.nodes[slot] = {n.bounds, children, 0};
    copy_subtree(from, n.index, children, out);
    copy_subtree(from, n.index + 1, children + 1, out);
}

// The top tree's leaves are subtree roots (its refs index `roots`): each is replaced by a copy of its subtree.
void assemble(const Bvh& top, uint32_t node, uint32_t slot, const std::vector<SubtreeRoot>& roots,
              const std::vector<Bvh>& mini_trees, Bvh& out) {
    const BvhNode& n = top.nodes[node];
    if (n.is_leaf()) {
        const SubtreeRoot& root = roots[top.refs[n.index]];
        copy_subtree(mini_trees[root.tree], root.node, slot, out);
        return;
    }
    const uint32_t children = uint32_t(out.nodes.size());
    out.nodes.resize(children + 2);
    out.nodes[slot] = {n.bounds, children, 0};
    assemble(top, n.index, children, roots, mini_trees, out);
    assemble(top, n.index + 1, children + 1, roots, mini_trees, out);
}

Bvh build_from_partitions(const Partitioning& partitioning, const BuildSettings& settings) {
    std::vector<Bvh> mini_trees(partitioning.partitions.size());
    parallel::for_each(mini_trees.size(), 1, [&](size_t i) {
        mini_trees[i] = build_sweep_sah_subtree(partitioning.partitions[i], settings, kMiniTreeMedianDepth);
    });
    BBox scene;
    for (const Bvh& tree : mini_trees)
        if (!tree.nodes.empty()) scene.extend(tree.nodes[0].bounds);
    std::vector<SubtreeRoot> roots;
    for (uint32_t i = 0; i < mini_trees.size(); ++i)
        if (!mini_trees[i].nodes.empty()) prune(mini_trees[i], i, 0, kPruneAreaFraction * scene.half_area(), roots);

    // The top tree: a sweep SAH over the subtree roots as primitives, one per leaf.
    std::vector<PrimRef> top_refs(roots.size());
    for (uint32_t i = 0; i < roots.size(); ++i) {
        const BBox& b = mini_trees[roots[i].tree].nodes[roots[i].node].bounds;
        top_refs[i] = {b.lower, i, b.upper};
    }
    BuildSettings top_settings = settings;
    top_settings.max_leaf_size = 1;
    top_settings.leaf_block = 1;
    const uint32_t top_levels = std::bit_width(uint32_t(roots.size()) - 1);  // ceil(log2(roots))
    const Bvh top = build_sweep_sah_subtree(top_refs, top_settings, kTopTreeMaxDepth - std::min(top_levels, kTopTreeMaxDepth));

    Bvh out;
    out.nodes.reserve(2 * partitioning.reference_count());
    out.refs.reserve(partitioning.reference_count());
    out.nodes.resize(1);
    assemble(top, 0, 0, roots, mini_trees, out);
    return out;
}

Bvh build_bonsai_variant(BuildInput&& input, const BuildSettings& settings, bool split) {
    if (input.refs.empty()) return {};
    const auto start = Clock::now();
    const Partitioning partitioning =
        partition_refs(input.triangles, input.refs, split_partition_threshold(input.refs.size()), split);
    const double split_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    Bvh bvh = build_from_partitions(partitioning, settings);
    if (split) bvh.split = {split_ms, partitioning.reference_capacity};
    return bvh;
}

}  // namespace

Bvh build_bonsai(BuildInput&& input, const BuildSettings& settings) {
    return build_bonsai_variant(std::move(input), settings, false);
}

Bvh build_bonsai_split(BuildInput&& input, const BuildSettings& settings) {
    return build_bonsai_variant(std::move(input), settings, true);
}

Bvh build_sweep_presplit(BuildInput&& input, const BuildSettings& settings) {
    if (input.refs.empty()) return {};
    const auto start = Clock::now();
    Partitioning partitioning =
        partition_refs(input.triangles, input.refs, split_partition_threshold(input.refs.size()), true);
    std::vector<PrimRef> refs = compact(partitioning);
    const uint64_t capacity = partitioning.reference_capacity;
    partitioning = {};
    const double split_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    Bvh bvh = build_sweep_sah(BuildInput{input.triangles, std::move(refs)}, settings);
    bvh.split = {split_ms, capacity};
    return bvh;
}

}  // namespace canopy
