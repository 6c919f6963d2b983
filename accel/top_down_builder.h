#pragma once
// The top-down SAH recursion that binned, sweep, sbvh and the two-level top level share: a node becomes a leaf
// when it holds one reference or when the SAH prices a leaf no dearer than the best split, and is cut at the median
// when no split is found, a split turns out degenerate, the node is too deep or it holds too many references for a
// leaf. Subtrees over at least `grain` references build as parallel tasks (SparseTree::set_inner). Each builder
// supplies only its split search, as a policy.
#include "accel/builder.h"
#include "accel/sparse_tree.h"

#include <concepts>
#include <optional>
#include <utility>

namespace canopy {

// What the driver asks of a split search. A Node is a range of references and whatever the search keeps about it
// (bounds, centroids, spare slots for references its splits add); a Split is the search's answer, its cost
// A_left T_left + A_right T_right in half areas and leaf tests.
template <class S>
concept SplitSearch = requires(S& s, typename S::Node& node, const typename S::Split& split) {
    { split.found() } -> std::convertible_to<bool>;
    { split.cost } -> std::convertible_to<float>;
    s.prepare(node);                                          // completes a node before it is decided on
    { s.count(node) } -> std::convertible_to<uint32_t>;       // its references
    { s.first(node) } -> std::convertible_to<uint32_t>;       // a leaf's first reference
    { s.slots(node) } -> std::convertible_to<uint32_t>;       // the reference slots it owns (its tree slots follow)
    { s.box(node) } -> std::convertible_to<BBox>;
    { s.half_area(node) } -> std::convertible_to<float>;
    { s.leaf_without_search(node) } -> std::convertible_to<bool>;  // a leaf known to beat any split
    { s.find(node) } -> std::same_as<typename S::Split>;
    // The children of a found split, or nothing when it turns out degenerate; and the children of a median cut.
    { s.split(node, split) } -> std::same_as<std::optional<std::pair<typename S::Node, typename S::Node>>>;
    { s.median(node) } -> std::same_as<std::pair<typename S::Node, typename S::Node>>;
};

struct TopDownLimits {
    uint32_t max_leaf;      // a node of more references is split even where the SAH prefers a leaf
    uint32_t median_depth;  // nodes this deep or deeper are cut at the median without a search
    size_t grain;           // subtrees over at least this many references build as parallel tasks
};

template <SplitSearch Search>
class TopDownBuilder {
public:
    using Node = typename Search::Node;

    // `settings` prices leaves against splits; `slots` is the number of reference slots the root owns.
    TopDownBuilder(Search& search, const BuildSettings& settings, const TopDownLimits& limits, size_t slots)
        : search_(search), settings_(settings), limits_(limits), nodes_(slots) {}

    BvhNodes build(const Node& root) {
        build_subtree(root, 0, 1, 0);
        return nodes_.finish();
    }

private:
    // Builds the subtree over `node` rooted at tree slot `slot`, its descendants from slot `descendants` on;
    // returns how far past `descendants` they reach (SparseTree::set_inner).
    uint32_t build_subtree(Node node, uint32_t slot, uint32_t descendants, uint32_t depth) {
        search_.prepare(node);
        const uint32_t n = search_.count(node);
        if (n == 1 || search_.leaf_without_search(node)) return leaf(node, slot);
        if (depth < limits_.median_depth) {
            const typename Search::Split split = search_.find(node);
            if (split.found() && !leaf_is_cheaper(node, n, split.cost)) {
                if (auto children = search_.split(node, split)) return inner(node, *children, slot, descendants, depth);
            }
        }
        if (n <= limits_.max_leaf) return leaf(node, slot);
        return inner(node, search_.median(node), slot, descendants, depth);
    }

    // A leaf that fits costs C_tri T(n) A, a split C_inn A plus its children's C_tri-weighted cost; ties go to leaves.
    bool leaf_is_cheaper(const Node& node, uint32_t n, float split_cost) const {
        if (n > limits_.max_leaf) return false;
        const float area = search_.half_area(node);
        const float split_total = settings_.costs.inner * area + settings_.costs.triangle * split_cost;
        return settings_.costs.triangle * settings_.leaf_tests(n) * area <= split_total;
    }

    uint32_t leaf(const Node& node, uint32_t slot) {
        return nodes_.set_leaf(slot, search_.box(node), search_.first(node), search_.count(node));
    }

    uint32_t inner(const Node& node, const std::pair<Node, Node>& children, uint32_t slot, uint32_t descendants,
                   uint32_t depth) {
        const auto& [left, right] = children;
        return nodes_.set_inner(
            slot, search_.box(node), descendants, search_.slots(left), search_.count(node), limits_.grain,
            [&](uint32_t first) { return build_subtree(left, descendants, first, depth + 1); },
            [&](uint32_t first) { return build_subtree(right, descendants + 1, first, depth + 1); });
    }

    Search& search_;
    const BuildSettings& settings_;
    const TopDownLimits limits_;
    SparseTree nodes_;
};

}  // namespace canopy
