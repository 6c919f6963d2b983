#pragma once
// The tree that optimisers restructure: a start Bvh turned into nodes that know their parents and keep their
// slots while they move. The start tree's leaves stay whole (single triangles from LBVH, small leaves from the
// SAH builders); to_bvh collapses subtrees into leaves where eq. 1 of the quality-metrics paper prefers them and
// emits a dense Bvh within kMaxBvhDepth.
#include "accel/builder.h"
#include "accel/parallel.h"

#include <utility>
#include <vector>

namespace canopy {

constexpr uint32_t kNoNode = ~0u;

struct MutableNode {
    BBox bounds;
    uint32_t parent = kNoNode;
    uint32_t child[2] = {kNoNode, kNoNode};  // inner nodes only
    uint32_t first_ref = 0;                  // leaf: the start tree's refs [first_ref, first_ref + ref_count)
    uint32_t ref_count = 0;                  // 0 marks an inner node
    uint32_t triangles = 0;                  // refs in the subtree

    bool is_leaf() const { return ref_count != 0; }
};

struct MutableTree {
    std::vector<MutableNode> nodes;  // slot i holds the start tree's node i until it moves
    uint32_t root = 0;
    std::vector<uint32_t> refs;      // the start tree's refs, which leaves index
    SplitReport split;               // the start tree's, passed on

    explicit MutableTree(Bvh&& start);

    MutableNode& operator[](uint32_t i) { return nodes[i]; }
    const MutableNode& operator[](uint32_t i) const { return nodes[i]; }
    float area(uint32_t i) const { return nodes[i].bounds.half_area(); }
    uint32_t slot_in_parent(uint32_t n) const { return nodes[nodes[n].parent].child[1] == n; }
    uint32_t sibling(uint32_t n) const { return nodes[nodes[n].parent].child[1 - slot_in_parent(n)]; }

    // Hangs `replacement` where `old` hangs (or makes it the root); `old` keeps a stale parent.
    void replace_in_parent(uint32_t old, uint32_t replacement);
    // Swaps two subtrees of which neither contains the other; their parents are not refitted.
    void swap_subtrees(uint32_t a, uint32_t b);
    // Bounds and triangle count of an inner node from its children.
    void refit(uint32_t n);
    void refit_to_root(uint32_t n);

    // Renumbers the nodes in depth-first order, so that subtrees that moved sit together in memory again.
    void relayout();

    // Nodes in breadth-first order from the root: reversed, every child comes before its parent.
    std::vector<uint32_t> breadth_first() const;
    // Sum of inner half areas: the only part of eq. 1 that moving whole leaves around changes.
    double inner_area() const;
    // Eq. 1 without the division by the root area, leaves charged settings.leaf_tests(refs) tests.
    double unnormalised_sah(const BuildSettings& settings) const;

    // The dense Bvh: a subtree becomes one leaf where that is no more expensive by eq. 1 (as Karras and Aila
    // 2013 collapse after optimising) and it holds at most settings.max_leaf_size refs. A subtree that
    // would reach past kMaxBvhDepth is rebuilt below kMedianFallbackDepth by median cuts over its leaves.
    Bvh to_bvh(const BuildSettings& settings) const;
};

namespace detail {

constexpr uint32_t kMaxForkDepth = 48;  // deeper subtrees run serially: bounds the recursion

template <class Visit>
void visit_post_order_serially(MutableTree& tree, uint32_t top, Visit& visit) {
    std::vector<std::pair<uint32_t, bool>> stack{{top, false}};
    while (!stack.empty()) {
        const auto [n, children_done] = stack.back();
        stack.pop_back();
        if (tree[n].is_leaf()) continue;
        if (children_done) {
            visit(n);
        } else {
            stack.push_back({n, true});
            stack.push_back({tree[n].child[1], false});
            stack.push_back({tree[n].child[0], false});
        }
    }
}

template <class Visit>
void visit_post_order(MutableTree& tree, uint32_t n, Visit& visit, uint32_t grain, uint32_t depth) {
    if (tree[n].is_leaf()) return;
    if (tree[n].triangles < grain || depth >= kMaxForkDepth) return visit_post_order_serially(tree, n, visit);
    const uint32_t left = tree[n].child[0], right = tree[n].child[1];
    parallel::fork_join(
        tree[n].triangles, grain, [&] { visit_post_order(tree, left, visit, grain, depth + 1); },
        [&] { visit_post_order(tree, right, visit, grain, depth + 1); });
    visit(n);
}

}  // namespace detail

// Visits every inner node after both its children (post order). Subtrees with at least `grain` triangles run
// concurrently; `visit(n)` may restructure n's subtree but nothing outside it, so the result does not depend on
// the number of threads.
template <class Visit>
void visit_inner_post_order(MutableTree& tree, Visit&& visit, uint32_t grain) {
    if (!tree.nodes.empty()) detail::visit_post_order(tree, tree.root, visit, grain, 0);
}

}  // namespace canopy
