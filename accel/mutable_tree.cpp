#include "accel/mutable_tree.h"

#include <algorithm>

namespace canopy {

MutableTree::MutableTree(Bvh&& start) : nodes(start.nodes.size()), refs(std::move(start.refs)), split(start.split) {
    for (uint32_t i = 0; i < start.nodes.size(); ++i) {
        const BvhNode& node = start.nodes[i];
        MutableNode& m = nodes[i];
        m.bounds = node.bounds;
        if (node.is_leaf()) {
            m.first_ref = node.index;
            m.ref_count = node.count;
            m.triangles = node.count;
        } else {
            for (uint32_t c = 0; c < 2; ++c) {
                m.child[c] = node.index + c;
                nodes[node.index + c].parent = i;
            }
        }
    }
    const std::vector<uint32_t> order = breadth_first();
    for (auto it = order.rbegin(); it != order.rend(); ++it)
        if (!nodes[*it].is_leaf()) refit(*it);
}

void MutableTree::replace_in_parent(uint32_t old, uint32_t replacement) {
    const uint32_t parent = nodes[old].parent;
    nodes[replacement].parent = parent;
    if (parent == kNoNode) root = replacement;
    else nodes[parent].child[slot_in_parent(old)] = replacement;
}

void MutableTree::swap_subtrees(uint32_t a, uint32_t b) {
    const uint32_t parent_a = nodes[a].parent, parent_b = nodes[b].parent;
    const uint32_t slot_a = slot_in_parent(a), slot_b = slot_in_parent(b);
    nodes[parent_a].child[slot_a] = b;
    nodes[parent_b].child[slot_b] = a;
    nodes[a].parent = parent_b;
    nodes[b].parent = parent_a;
}

void MutableTree::refit(uint32_t n) {
    const MutableNode& left = nodes[nodes[n].child[0]];
    const MutableNode& right = nodes[nodes[n].child[1]];
    nodes[n].bounds = merge(left.bounds, right.bounds);
    nodes[n].triangles = left.triangles + right.triangles;
}

void MutableTree::refit_to_root(uint32_t n) {
    for (; n != kNoNode; n = nodes[n].parent) refit(n);
}

void MutableTree::relayout() {
    if (nodes.empty()) return;
    std::vector<MutableNode> laid_out;
    laid_out.reserve(nodes.size());
    struct Pending { uint32_t old, parent, slot_in_parent; };
    std::vector<Pending> stack{{root, kNoNode, 0}};
    while (!stack.empty()) {
        const Pending p = stack.back();
        stack.pop_back();
        const uint32_t slot = uint32_t(laid_out.size());
        laid_out.push_back(nodes[p.old]);
        laid_out.back().parent = p.parent;
        if (p.parent != kNoNode) laid_out[p.parent].child[p.slot_in_parent] = slot;
        if (!nodes[p.old].is_leaf())
            for (uint32_t c = 2; c-- > 0;) stack.push_back({nodes[p.old].child[c], slot, c});
    }
    nodes = std::move(laid_out);
    root = 0;
}

std::vector<uint32_t> MutableTree::breadth_first() const {
    std::vector<uint32_t> order;
    if (nodes.empty()) return order;
    order.reserve(nodes.size());
    order.push_back(root);
    for (size_t i = 0; i < order.size(); ++i)
        if (!nodes[order[i]].is_leaf()) order.insert(order.end(), nodes[order[i]].child, nodes[order[i]].child + 2);
    return order;
}

double MutableTree::inner_area() const {
    double sum = 0.0;
    for (uint32_t n : breadth_first())
        if (!nodes[n].is_leaf()) sum += area(n);
    return sum;
}

double MutableTree::unnormalised_sah(const BuildSettings& settings) const {
    double inner = 0.0, leaves = 0.0;
    for (uint32_t n : breadth_first()) {
        if (nodes[n].is_leaf()) leaves += double(settings.leaf_tests(nodes[n].ref_count)) * area(n);
        else inner += area(n);
    }
    return settings.costs.inner * inner + settings.costs.triangle * leaves;
}

namespace {

class BvhEmitter {
public:
    BvhEmitter(const MutableTree& tree, const BuildSettings& settings)
        : tree_(tree), settings_(settings), collapsed_(tree.nodes.size(), 0), height_(tree.nodes.size(), 0) {
        choose_leaves();
    }

    Bvh emit() {
        bvh_.split = tree_.split;
        if (tree_.nodes.empty()) return std::move(bvh_);
        bvh_.nodes.reserve(tree_.nodes.size());
        bvh_.refs.reserve(tree_.refs.size());
        bvh_.nodes.emplace_back();
        struct Pending { uint32_t node, out, depth; };
        std::vector<Pending> stack{{tree_.root, 0, 0}};
        while (!stack.empty()) {
            const Pending p = stack.back();
            stack.pop_back();
            if (emits_leaf(p.node)) {
                emit_leaf(p.node, p.out);
            } else if (p.depth >= kMedianFallbackDepth && p.depth + height_[p.node] > kMaxBvhDepth) {
                std::vector<uint32_t> units = emitted_leaves_below(p.node);
                emit_median_cuts(units.data(), units.data() + units.size(), p.out);
            } else {
                const uint32_t first = allocate_children(p.out, tree_[p.node].bounds);
                for (uint32_t c = 2; c-- > 0;) stack.push_back({tree_[p.node].child[c], first + c, p.depth + 1});
            }
        }
        return std::move(bvh_);
    }

private:
    bool emits_leaf(uint32_t n) const { return tree_[n].is_leaf() || collapsed_[n]; }

    // Bottom up: a subtree becomes a leaf where eq. 1 charges a leaf of all its refs no more than the subtree.
    void choose_leaves() {
        if (tree_.nodes.empty()) return;
        std::vector<double> cost(tree_.nodes.size());
        const std::vector<uint32_t> order = tree_.breadth_first();
        for (auto it = order.rbegin(); it != order.rend(); ++it) {
            const uint32_t n = *it;
            const MutableNode& node = tree_[n];
            const double area = tree_.area(n);
            const double as_leaf = settings_.costs.triangle * settings_.leaf_tests(node.triangles) * area;
            if (node.is_leaf()) {
                cost[n] = as_leaf;
                continue;
            }
            const double as_inner = settings_.costs.inner * area + cost[node.child[0]] + cost[node.child[1]];
            collapsed_[n] = node.triangles <= settings_.max_leaf_size && as_leaf <= as_inner;
            cost[n] = collapsed_[n] ? as_leaf : as_inner;
            height_[n] = collapsed_[n] ? 0 : 1 + std::max(height_[node.child[0]], height_[node.child[1]]);
        }
    }

    uint32_t allocate_children(uint32_t out, const BBox& bounds) {
        const uint32_t first = uint32_t(bvh_.nodes.size());
        bvh_.nodes[out] = {bounds, first, 0};
        bvh_.nodes.resize(first + 2);
        return first;
    }

    // A leaf with the refs of every start leaf below n, left to right.
    void emit_leaf(uint32_t n, uint32_t out) {
        const uint32_t first = uint32_t(bvh_.refs.size());
        std::vector<uint32_t> stack{n};
        while (!stack.empty()) {
            const MutableNode& node = tree_[stack.back()];
            stack.pop_back();
            if (node.is_leaf()) {
                bvh_.refs.insert(bvh_.refs.end(), tree_.refs.begin() + node.first_ref,
                                 tree_.refs.begin() + node.first_ref + node.ref_count);
            } else {
                stack.push_back(node.child[1]);
                stack.push_back(node.child[0]);
            }
        }
        bvh_.nodes[out] = {tree_[n].bounds, first, uint32_t(bvh_.refs.size()) - first};
    }

    std::vector<uint32_t> emitted_leaves_below(uint32_t n) const {
        std::vector<uint32_t> units, stack{n};
        while (!stack.empty()) {
            const uint32_t m = stack.back();
            stack.pop_back();
            if (emits_leaf(m)) {
                units.push_back(m);
            } else {
                stack.push_back(tree_[m].child[1]);
                stack.push_back(tree_[m].child[0]);
            }
        }
        return units;
    }

    // Median cuts along the largest centroid extent: at most ceil(log2(units)) <= 32 levels, so a subtree
    // started at kMedianFallbackDepth ends within kMaxBvhDepth.
    void emit_median_cuts(uint32_t* begin, uint32_t* end, uint32_t out) {
        if (end - begin == 1) return emit_leaf(*begin, out);
        BBox bounds, centroids;
        for (const uint32_t* u = begin; u != end; ++u) {
            bounds.extend(tree_[*u].bounds);
            centroids.extend(tree_[*u].bounds.center());
        }
        const int axis = centroids.largest_axis();
        uint32_t* middle = begin + (end - begin) / 2;
        std::nth_element(begin, middle, end, [&](uint32_t a, uint32_t b) {
            const float ca = tree_[a].bounds.center()[axis], cb = tree_[b].bounds.center()[axis];
            return ca < cb || (ca == cb && a < b);
        });
        const uint32_t first = allocate_children(out, bounds);
        emit_median_cuts(begin, middle, first);
        emit_median_cuts(middle, end, first + 1);
    }

    const MutableTree& tree_;
    const BuildSettings& settings_;
    std::vector<uint8_t> collapsed_;   // by node: the subtree becomes one leaf
    std::vector<uint32_t> height_;     // by node: levels below it once collapsed subtrees are leaves
    Bvh bvh_;
};

}  // namespace

Bvh MutableTree::to_bvh(const BuildSettings& settings) const { return BvhEmitter(*this, settings).emit(); }

}  // namespace canopy
