#include "accel/builders/bittner_reinsertion.h"

#include "accel/mutable_tree.h"

#include <algorithm>
#include <limits>
#include <queue>

namespace canopy {
namespace {

constexpr double kBatchShare = 0.1;          // inner nodes removed per batch
constexpr uint32_t kWindow = 3;              // batches over which the SAH must fall by kMinImprovement
constexpr double kMinImprovement = 0.01;
constexpr uint32_t kMaxBatches = 30;         // caps the work at 3 removals per inner node

class Reinsertion {
public:
    Reinsertion(MutableTree& tree, const BuildSettings& settings) : tree_(tree), settings_(settings) {}

    void optimise() {
        const size_t inner = tree_.nodes.size() / 2;
        const size_t batch = std::max<size_t>(1, size_t(kBatchShare * double(inner)));
        std::vector<double> history{tree_.unnormalised_sah(settings_)};
        MutableTree best = tree_;
        for (uint32_t b = 0; b < kMaxBatches; ++b) {
            for (uint32_t n : most_inefficient(batch)) reinsert_children(n);
            history.push_back(tree_.unnormalised_sah(settings_));
            if (history.back() < *std::min_element(history.begin(), history.end() - 1)) best = tree_;
            if (history.size() > kWindow &&
                history[history.size() - 1 - kWindow] - history.back() < kMinImprovement * history.back())
                break;
        }
        if (tree_.unnormalised_sah(settings_) > best.unnormalised_sah(settings_)) tree_ = std::move(best);
    }

private:
    // The paper's combined measure: a node is inefficient when its box is large and much larger than its children's.
    double inefficiency(uint32_t n) const {
        const double area = tree_.area(n);
        const double a = tree_.area(tree_[n].child[0]), b = tree_.area(tree_[n].child[1]);
        const double m_sum = area / (0.5 * (a + b)), m_min = area / std::min(a, b);
        return (a + b > 0.0 && std::min(a, b) > 0.0) ? m_sum * m_min * area
                                                     : std::numeric_limits<double>::infinity();
    }

    // Inner nodes other than the root, most inefficient first; ties by slot.
    std::vector<uint32_t> most_inefficient(size_t count) const {
        std::vector<std::pair<double, uint32_t>> candidates;
        for (uint32_t n = 0; n < tree_.nodes.size(); ++n)
            if (!tree_[n].is_leaf() && n != tree_.root) candidates.push_back({-inefficiency(n), n});
        count = std::min(count, candidates.size());
        std::partial_sort(candidates.begin(), candidates.begin() + count, candidates.end());
        std::vector<uint32_t> nodes(count);
        for (size_t i = 0; i < count; ++i) nodes[i] = candidates[i].second;
        return nodes;
    }

    // Removes n and its parent (n's sibling takes the parent's place) and reinserts n's children, the larger
    // first, with n and its parent as their new parents.
    void reinsert_children(uint32_t n) {
        if (tree_[n].is_leaf() || n == tree_.root) return;  // an earlier reinsertion made n the root
        const uint32_t parent = tree_[n].parent;
        const uint32_t sibling = tree_.sibling(n);
        const uint32_t grandparent = tree_[parent].parent;
        tree_.replace_in_parent(parent, sibling);
        if (grandparent != kNoNode) tree_.refit_to_root(grandparent);
        uint32_t first = tree_[n].child[0], second = tree_[n].child[1];
        if (tree_.area(second) > tree_.area(first)) std::swap(first, second);
        insert(first, n);
        insert(second, parent);
    }

    void insert(uint32_t node, uint32_t new_parent) {
        const uint32_t sibling = best_sibling(tree_[node].bounds);
        tree_.replace_in_parent(sibling, new_parent);
        tree_[new_parent].child[0] = sibling;
        tree_[new_parent].child[1] = node;
        tree_[sibling].parent = new_parent;
        tree_[node].parent = new_parent;
        tree_.refit_to_root(new_parent);
    }

    // The paper's search: placing the box beside x costs the new parent's area plus the growth of x's ancestors (the
    // induced cost); a subtree is searched only while its lower bound, induced cost + growth of x + the box's own
    // area, beats the best placement found.
    uint32_t best_sibling(const BBox& box) {
        const float own_area = box.half_area();
        float best_cost = std::numeric_limits<float>::infinity();
        uint32_t best = tree_.root;
        queue_ = {};
        queue_.push({0.0f, tree_.root});
        while (!queue_.empty()) {
            const auto [induced, x] = queue_.top();
            queue_.pop();
            if (induced + own_area >= best_cost) break;
            const float merged = merge(tree_[x].bounds, box).half_area();
            if (induced + merged < best_cost) {
                best_cost = induced + merged;
                best = x;
            }
            if (tree_[x].is_leaf()) continue;
            const float child_induced = induced + merged - tree_.area(x);
            if (child_induced + own_area < best_cost)
                for (uint32_t c : tree_[x].child) queue_.push({child_induced, c});
        }
        return best;
    }

    using Candidate = std::pair<float, uint32_t>;  // induced cost, node: the cheapest on top, ties by slot
    MutableTree& tree_;
    const BuildSettings& settings_;
    std::priority_queue<Candidate, std::vector<Candidate>, std::greater<Candidate>> queue_;
};

}  // namespace

Bvh build_bittner(BuildInput&& input, const BuildSettings& settings) {
    MutableTree tree(build_start_tree(std::move(input), settings, "lbvh"));
    Reinsertion(tree, settings).optimise();
    return tree.to_bvh(settings);
}

}  // namespace canopy
