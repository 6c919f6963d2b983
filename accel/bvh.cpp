#include "accel/bvh.h"
#include "accel/bvh_compact.h"
#include "accel/builder.h"
#include "accel/parallel.h"
#include "base/huge_pages.h"

namespace canopy {

BvhNodes compact_sparse_nodes(const BvhNode* sparse) {
    BvhNodes dense;
    dense.push_back(sparse[0]);
    struct Pending { uint32_t dense_index, sparse_children; };
    std::vector<Pending> stack;
    if (!sparse[0].is_leaf()) stack.push_back({0, sparse[0].index});
    while (!stack.empty()) {
        const Pending p = stack.back();
        stack.pop_back();
        const uint32_t first = uint32_t(dense.size());
        dense[p.dense_index].index = first;
        for (uint32_t c = 0; c < 2; ++c) dense.push_back(sparse[p.sparse_children + c]);
        for (uint32_t c = 2; c-- > 0;)  // right pushed first: the left subtree is laid out next
            if (!dense[first + c].is_leaf()) stack.push_back({first + c, dense[first + c].index});
    }
    return dense;
}

double sah_cost(const Bvh& bvh, SahCosts costs) {
    if (bvh.nodes.empty()) return 0.0;
    double inner = 0.0, leaves = 0.0;
    for (const BvhNode& node : bvh.nodes) {
        const double area = node.bounds.half_area();
        if (node.is_leaf()) leaves += double(node.count) * area;
        else inner += area;
    }
    const double root_area = bvh.nodes[0].bounds.half_area();
    if (root_area <= 0.0) return costs.triangle * double(bvh.refs.size());
    return (costs.inner * inner + costs.triangle * leaves) / root_area;
}

TreeStats tree_stats(const Bvh& bvh, uint64_t triangle_count) {
    TreeStats s;
    s.nodes = bvh.nodes.size();
    s.bytes = bvh.nodes.size() * sizeof(BvhNode) + bvh.refs.size() * sizeof(uint32_t);
    if (bvh.nodes.empty()) return s;
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
    while (!stack.empty()) {
        const auto [index, depth] = stack.back();
        stack.pop_back();
        const BvhNode& node = bvh.nodes[index];
        s.depth = std::max(s.depth, depth);
        if (node.is_leaf()) {
            ++s.leaves;
            s.references += node.count;
            s.max_leaf_size = std::max<uint64_t>(s.max_leaf_size, node.count);
        } else {
            ++s.inner_nodes;
            stack.push_back({node.index, depth + 1});
            stack.push_back({node.index + 1, depth + 1});
        }
    }
    s.refs_per_triangle = triangle_count ? double(s.references) / double(triangle_count) : 0.0;
    return s;
}

std::vector<PrimRef> make_prim_refs(std::span<const Triangle> triangles) {
    std::vector<PrimRef> refs;
    resize_on_huge_pages(refs, triangles.size());
    parallel::for_each(triangles.size(), 16 * 1024, [&](size_t i) {
        const BBox box = BBox::of(triangles[i]);
        refs[i] = {box.lower, uint32_t(i), box.upper, 0};
    });
    return refs;
}

}  // namespace canopy
