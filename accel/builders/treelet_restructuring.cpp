#include "accel/builders/treelet_restructuring.h"

#include "accel/mutable_tree.h"

#include <array>
#include <bit>
#include <limits>

namespace canopy {
namespace {

constexpr uint32_t kTreeletLeaves = 7;
constexpr uint32_t kSubsets = 1u << kTreeletLeaves;
constexpr uint32_t kRounds = 3;
constexpr uint32_t kFirstGamma = 7;               // doubled every round
constexpr uint32_t kParallelGrain = 4 * 1024;     // triangles under a subtree worth a task
constexpr double kMinRelativeGain = 1e-9;         // rebuild only on a real improvement, not on rounding

class TreeletOptimiser {
public:
    TreeletOptimiser(MutableTree& tree, const BuildSettings& settings)
        : tree_(tree), settings_(settings), cost_(tree.nodes.size()) {}

    void optimise() {
        for (uint32_t round = 0, gamma = kFirstGamma; round < kRounds; ++round, gamma *= 2) {
            tree_.relayout();  // restructuring scatters subtrees in memory: lay them out again
            const std::vector<uint32_t> order = tree_.breadth_first();
            for (auto it = order.rbegin(); it != order.rend(); ++it) cost_[*it] = subtree_cost(*it);
            visit_inner_post_order(tree_, [&](uint32_t n) {
                cost_[n] = subtree_cost(n);
                if (tree_[n].triangles >= gamma) restructure(n);
            }, kParallelGrain);
        }
    }

private:
    struct Treelet {
        std::array<uint32_t, kTreeletLeaves> leaves;
        std::array<uint32_t, kTreeletLeaves - 1> inner;  // inner[0] is the treelet's root
        uint32_t leaf_count = 0;
    };

    // Eq. 1 over the subtree, unnormalised, with the collapse into one leaf where that is cheaper (as the paper).
    double subtree_cost(uint32_t n) const {
        const MutableNode& node = tree_[n];
        if (node.is_leaf()) return leaf_cost(tree_.area(n), node.ref_count);
        const double as_inner = settings_.costs.inner * tree_.area(n) + cost_[node.child[0]] + cost_[node.child[1]];
        return std::min(as_inner, collapse_cost(tree_.area(n), node.triangles));
    }
    double leaf_cost(double area, uint32_t refs) const {
        return settings_.costs.triangle * settings_.leaf_tests(refs) * area;
    }
    double collapse_cost(double area, uint32_t refs) const {
        return refs <= settings_.max_leaf_size ? leaf_cost(area, refs) : std::numeric_limits<double>::infinity();
    }

    // Sec. 4: grow from the root's children, always expanding the treelet leaf with the largest area.
    Treelet form_treelet(uint32_t root) const {
        Treelet t;
        t.inner[0] = root;
        t.leaves[0] = tree_[root].child[0];
        t.leaves[1] = tree_[root].child[1];
        t.leaf_count = 2;
        while (t.leaf_count < kTreeletLeaves) {
            int largest = -1;
            for (uint32_t i = 0; i < t.leaf_count; ++i)
                if (!tree_[t.leaves[i]].is_leaf() && (largest < 0 || tree_.area(t.leaves[i]) > tree_.area(t.leaves[largest])))
                    largest = int(i);
            if (largest < 0) break;
            const uint32_t expanded = t.leaves[largest];
            t.inner[t.leaf_count - 1] = expanded;
            t.leaves[largest] = tree_[expanded].child[0];
            t.leaves[t.leaf_count++] = tree_[expanded].child[1];
        }
        return t;
    }

    void restructure(uint32_t root) {
        const Treelet t = form_treelet(root);
        if (t.leaf_count < 3) return;  // two leaves have one arrangement
        const uint32_t full = (1u << t.leaf_count) - 1;
        std::array<BBox, kSubsets> bounds;
        std::array<uint32_t, kSubsets> triangles;
        bounds[0] = {};
        triangles[0] = 0;
        for (uint32_t s = 1; s <= full; ++s) {
            const uint32_t low = uint32_t(std::countr_zero(s));
            bounds[s] = merge(bounds[s & (s - 1)], tree_[t.leaves[low]].bounds);
            triangles[s] = triangles[s & (s - 1)] + tree_[t.leaves[low]].triangles;
        }
        // Algorithm 2: optimal costs of subsets by increasing size; each partition {p, s \ p} is tried once.
        std::array<double, kSubsets> cost;
        std::array<uint32_t, kSubsets> partition{};
        for (uint32_t i = 0; i < t.leaf_count; ++i) cost[1u << i] = cost_[t.leaves[i]];
        for (uint32_t size = 2; size <= t.leaf_count; ++size) {
            for (uint32_t s = 1; s <= full; ++s) {
                if (uint32_t(std::popcount(s)) != size) continue;
                double best = std::numeric_limits<double>::infinity();
                const uint32_t delta = (s - 1) & s;
                for (uint32_t p = (0u - delta) & s; p != 0; p = (p - delta) & s) {
                    const double c = cost[p] + cost[s ^ p];
                    if (c < best) {
                        best = c;
                        partition[s] = p;
                    }
                }
                const double area = bounds[s].half_area();
                cost[s] = std::min(settings_.costs.inner * area + best, collapse_cost(area, triangles[s]));
            }
        }
        if (cost[full] >= cost_[root] * (1.0 - kMinRelativeGain)) return;
        uint32_t next_inner = 1;
        rebuild(t, full, bounds, triangles, cost, partition, next_inner);
    }

    // Rebuilds subset s of the treelet's leaves by its optimal partition, reusing the treelet's inner slots.
    uint32_t rebuild(const Treelet& t, uint32_t s, const std::array<BBox, kSubsets>& bounds,
                     const std::array<uint32_t, kSubsets>& triangles, const std::array<double, kSubsets>& cost,
                     const std::array<uint32_t, kSubsets>& partition, uint32_t& next_inner) {
        if (std::has_single_bit(s)) return t.leaves[std::countr_zero(s)];
        const uint32_t n = s == (1u << t.leaf_count) - 1 ? t.inner[0] : t.inner[next_inner++];
        const uint32_t left = rebuild(t, partition[s], bounds, triangles, cost, partition, next_inner);
        const uint32_t right = rebuild(t, s ^ partition[s], bounds, triangles, cost, partition, next_inner);
        MutableNode& node = tree_[n];
        node.child[0] = left;
        node.child[1] = right;
        node.bounds = bounds[s];
        node.triangles = triangles[s];
        tree_[left].parent = n;
        tree_[right].parent = n;
        cost_[n] = cost[s];
        return n;
    }

    MutableTree& tree_;
    const BuildSettings& settings_;
    std::vector<double> cost_;  // by node: subtree_cost, kept current below the node being visited
};

}  // namespace

void optimise_treelets(Bvh& bvh, const BuildSettings& settings) {
    MutableTree tree(std::move(bvh));
    TreeletOptimiser(tree, settings).optimise();
    bvh = tree.to_bvh(settings);
}

Bvh build_treelet(BuildInput&& input, const BuildSettings& settings) {
    Bvh bvh = build_start_tree(std::move(input), settings, "lbvh");
    optimise_treelets(bvh, settings);
    return bvh;
}

}  // namespace canopy
