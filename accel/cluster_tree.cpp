#include "accel/cluster_tree.h"

#include <algorithm>
#include <span>
#include <stdexcept>

namespace canopy {

ClusterTree::ClusterTree(const std::vector<PrimRef>& refs) : leaves_(uint32_t(refs.size())), bounds_(refs.size()) {
    for (size_t i = 0; i < refs.size(); ++i) bounds_[i] = refs[i].bounds();
}

uint32_t ClusterTree::merge(uint32_t a, uint32_t b) {
    children_.push_back({a, b});
    bounds_.push_back(canopy::merge(bounds_[a], bounds_[b]));
    return uint32_t(bounds_.size() - 1);
}

void ClusterTree::reserve_merges(uint32_t merges) {
    children_.resize(merges);
    bounds_.resize(size_t(leaves_) + merges);
}

void ClusterTree::set_merge(uint32_t k, uint32_t a, uint32_t b) {
    children_[k] = {a, b};
    bounds_[leaves_ + k] = canopy::merge(bounds_[a], bounds_[b]);
}

namespace {

class BvhWriter {
public:
    BvhWriter(const std::vector<std::array<uint32_t, 2>>& children, const std::vector<BBox>& bounds,
              const std::vector<PrimRef>& refs)
        : children_(children), bounds_(bounds), refs_(refs), leaves_(uint32_t(refs.size())), height_(bounds.size(), 0) {
        // Children have lower ids than their parent, so one pass in id order gives every height.
        for (uint32_t k = 0; k < children_.size(); ++k)
            height_[leaves_ + k] = 1 + std::max(height_[children_[k][0]], height_[children_[k][1]]);
        bvh_.nodes.reserve(2 * size_t(leaves_) - 1);
        bvh_.refs.reserve(leaves_);
    }

    Bvh write(uint32_t root) {
        bvh_.nodes.push_back({});
        write_cluster(root, 0, 0);
        return std::move(bvh_);
    }

private:
    bool is_leaf(uint32_t cluster) const { return cluster < leaves_; }

    // Fills node slot `node` with the subtree of `cluster` at depth `depth`.
    void write_cluster(uint32_t cluster, uint32_t node, uint32_t depth) {
        if (depth == kMedianFallbackDepth && height_[cluster] > kMaxBvhDepth - depth) {
            std::vector<uint32_t> leaves;
            collect_leaves(cluster, leaves);
            write_median_split(leaves, node);
            return;
        }
        if (is_leaf(cluster)) {
            write_leaf(cluster, node);
            return;
        }
        const uint32_t first = add_children(node, bounds_[cluster]);
        write_cluster(children_[cluster - leaves_][0], first, depth + 1);
        write_cluster(children_[cluster - leaves_][1], first + 1, depth + 1);
    }

    void write_leaf(uint32_t cluster, uint32_t node) {
        bvh_.nodes[node] = {bounds_[cluster], uint32_t(bvh_.refs.size()), 1};
        bvh_.refs.push_back(refs_[cluster].prim);
    }

    uint32_t add_children(uint32_t node, const BBox& bounds) {
        const uint32_t first = uint32_t(bvh_.nodes.size());
        bvh_.nodes[node] = {bounds, first, 0};
        bvh_.nodes.resize(first + 2);
        return first;
    }

    void collect_leaves(uint32_t cluster, std::vector<uint32_t>& leaves) const {
        std::vector<uint32_t> stack{cluster};
        while (!stack.empty()) {
            const uint32_t c = stack.back();
            stack.pop_back();
            if (is_leaf(c)) {
                leaves.push_back(c);
            } else {
                stack.push_back(children_[c - leaves_][1]);
                stack.push_back(children_[c - leaves_][0]);
            }
        }
    }

    // A balanced subtree over `leaves`: halves at the median centroid along the widest centroid axis.
    void write_median_split(std::span<uint32_t> leaves, uint32_t node) {
        if (leaves.size() == 1) {
            write_leaf(leaves[0], node);
            return;
        }
        BBox box, centroids;
        for (const uint32_t c : leaves) {
            box.extend(bounds_[c]);
            centroids.extend(bounds_[c].center());
        }
        const int axis = centroids.largest_axis();
        const auto middle = leaves.begin() + leaves.size() / 2;
        std::nth_element(leaves.begin(), middle, leaves.end(), [&](uint32_t a, uint32_t b) {
            const float ca = bounds_[a].center()[axis], cb = bounds_[b].center()[axis];
            return ca != cb ? ca < cb : a < b;
        });
        const uint32_t first = add_children(node, box);
        write_median_split(leaves.first(leaves.size() / 2), first);
        write_median_split(leaves.subspan(leaves.size() / 2), first + 1);
    }

    const std::vector<std::array<uint32_t, 2>>& children_;
    const std::vector<BBox>& bounds_;
    const std::vector<PrimRef>& refs_;
    const uint32_t leaves_;
    std::vector<uint32_t> height_;  // edges to the deepest leaf below, by cluster
    Bvh bvh_;
};

}  // namespace

Bvh ClusterTree::to_bvh(const std::vector<PrimRef>& refs) const {
    if (children_.size() + 1 != leaves_) throw std::logic_error("cluster tree: clustering did not end in one root");
    return BvhWriter(children_, bounds_, refs).write(uint32_t(bounds_.size() - 1));
}

}  // namespace canopy
