#include "accel/builders/lbvh_sah.h"

#include "accel/bvh_compact.h"
#include "accel/builders/lbvh.h"
#include "accel/parallel.h"

namespace canopy {
namespace {

// Levels below the root whose two subtrees are collapsed concurrently: 2^10 tasks, plenty for any thread count.
constexpr uint32_t kParallelDepth = 10;

class LeafCollapser {
public:
    LeafCollapser(Bvh& bvh, const BuildSettings& settings) : bvh_(bvh), settings_(settings) {}

    // Returns the subtree's triangle count and SAH cost (in half areas); turns it into one leaf where cheaper.
    // An LBVH subtree's refs are one contiguous run, the left child's first, so a leaf takes them in place.
    std::pair<uint32_t, float> collapse(uint32_t index, uint32_t depth) {
        BvhNode& node = bvh_.nodes[index];
        const float area = node.bounds.half_area();
        if (node.is_leaf()) return {node.count, settings_.costs.triangle * settings_.leaf_tests(node.count) * area};
        std::pair<uint32_t, float> left, right;
        parallel::fork_join(depth < kParallelDepth ? 2 : 0, 2,
                            [&] { left = collapse(node.index, depth + 1); },
                            [&] { right = collapse(node.index + 1, depth + 1); });
        const uint32_t count = left.first + right.first;
        const float subtree_cost = settings_.costs.inner * area + left.second + right.second;
        const float leaf_cost = settings_.costs.triangle * settings_.leaf_tests(count) * area;
        if (count <= settings_.max_leaf_size && leaf_cost <= subtree_cost) {
            node = {node.bounds, first_ref(node.index), count};
            return {count, leaf_cost};
        }
        return {count, subtree_cost};
    }

private:
    uint32_t first_ref(uint32_t index) const {
        while (!bvh_.nodes[index].is_leaf()) index = bvh_.nodes[index].index;
        return bvh_.nodes[index].index;
    }

    Bvh& bvh_;
    const BuildSettings& settings_;
};

}  // namespace

Bvh build_lbvh_sah(BuildInput&& input, const BuildSettings& settings) {
    Bvh bvh = build_lbvh(std::move(input), settings);
    if (bvh.nodes.empty()) return bvh;
    bvh.one_ref_leaves.clear();
    LeafCollapser(bvh, settings).collapse(0, 0);
    bvh.nodes = compact_sparse_nodes(bvh.nodes.data());  // drops the nodes beneath the new leaves
    return bvh;
}

}  // namespace canopy
