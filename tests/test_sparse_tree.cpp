// SparseTree (accel/sparse_tree.h): subtrees built concurrently keep to their reserved slots, serial ones pack their
// nodes, and the compacted tree does not depend on which ran how, even where a subtree built serially has a
// descendant built concurrently (the two-level builder's work grows as it opens instances).
#include "accel/sparse_tree.h"

#include <catch2/catch.hpp>

#include <atomic>
#include <cstring>
#include <functional>
#include <vector>

using namespace canopy;

namespace {

// Whether the node at `depth` over `refs` refs builds its children concurrently.
using Concurrency = std::function<bool(uint32_t depth, uint32_t refs)>;

struct UnevenBuilder {
    SparseTree& nodes;
    const Concurrency& concurrent;
    uint32_t max_leaf;  // above 1, subtrees use fewer slots than are reserved for them
    std::atomic<uint32_t> overreaching{0};  // subtrees reaching past their reserved range (Catch2 checks only on one thread)

    // A tree over refs [begin, end), split a third of the way down to leaves of at most max_leaf; returns set_inner's
    // reach.
    uint32_t build(uint32_t begin, uint32_t end, uint32_t node, uint32_t descendants, uint32_t depth) {
        const uint32_t n = end - begin;
        if (n <= max_leaf) return nodes.set_leaf(node, BBox{Vec3(float(begin)), Vec3(float(end))}, begin, n);
        const uint32_t mid = begin + n / 3 + 1;
        const uint32_t reach = nodes.set_inner(
            node, BBox{Vec3(float(begin)), Vec3(float(end))}, descendants, mid - begin, concurrent(depth, n) ? 2 : 0, 1,
            [&](uint32_t first) { return build(begin, mid, descendants, first, depth + 1); },
            [&](uint32_t first) { return build(mid, end, descendants + 1, first, depth + 1); });
        if (reach > 2 * n - 2) ++overreaching;  // past the range reserved for n refs
        return reach;
    }
};

BvhNodes build_uneven(uint32_t refs, uint32_t max_leaf, const Concurrency& concurrent) {
    SparseTree nodes(refs);
    UnevenBuilder builder{nodes, concurrent, max_leaf};
    builder.build(0, refs, 0, 1, 0);
    CHECK(builder.overreaching == 0);
    return nodes.finish();
}

bool same_nodes(const BvhNodes& a, const BvhNodes& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(BvhNode)) == 0;
}

}  // namespace

TEST_CASE("a sparse tree compacts to the same nodes however its subtrees were built", "[sparse-tree]") {
    for (const uint32_t max_leaf : {1u, 2u, 3u})
        for (const uint32_t refs : {1u, 2u, 3u, 7u, 100u, 1000u}) {
            INFO(refs << " refs, leaves of at most " << max_leaf);
            const BvhNodes serial = build_uneven(refs, max_leaf, [](uint32_t, uint32_t) { return false; });
            uint32_t leaves = 0, leaf_refs = 0;
            for (const BvhNode& node : serial) leaves += node.is_leaf(), leaf_refs += node.count;
            CHECK(serial.size() == 2 * leaves - 1);
            CHECK(leaf_refs == refs);
            CHECK(same_nodes(serial, build_uneven(refs, max_leaf, [](uint32_t, uint32_t) { return true; })));
            CHECK(same_nodes(serial, build_uneven(refs, max_leaf, [](uint32_t depth, uint32_t) { return depth >= 2; })));
            CHECK(same_nodes(serial, build_uneven(refs, max_leaf, [](uint32_t depth, uint32_t) { return depth % 2 == 1; })));
            CHECK(same_nodes(serial, build_uneven(refs, max_leaf, [](uint32_t, uint32_t n) { return n % 3 == 0; })));
        }
}

TEST_CASE("a compacted sparse tree lists each node's subtree depth first, children side by side", "[sparse-tree]") {
    const BvhNodes nodes = build_uneven(5, 1, [](uint32_t depth, uint32_t) { return depth == 1; });
    // Refs 0-4 split into 0-1 | 2-4, 0-1 into 0 | 1, 2-4 into 2-3 | 4 and 2-3 into 2 | 3.
    REQUIRE(nodes.size() == 9);
    CHECK(nodes[0].index == 1);  // the root's children: 1 (refs 0-1) and 2 (refs 2-4)
    CHECK(nodes[1].index == 3);  // the left subtree comes first
    CHECK((nodes[3].is_leaf() && nodes[3].index == 0));
    CHECK((nodes[4].is_leaf() && nodes[4].index == 1));
    CHECK(nodes[2].index == 5);  // then the right one
    CHECK(nodes[5].index == 7);
    CHECK((nodes[6].is_leaf() && nodes[6].index == 4));
    CHECK((nodes[7].is_leaf() && nodes[7].index == 2));
    CHECK((nodes[8].is_leaf() && nodes[8].index == 3));
}
