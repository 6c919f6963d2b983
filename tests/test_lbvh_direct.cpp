// lbvh's wide trees emitted straight from the Morton codes (accel/builders/lbvh_direct.h): the tree its comment
// specifies, the same with any number of threads, and the same answers as brute force at every scale.
#include "accel/morton.h"
#include "accel/metrics.h"
#include "oracle.h"
#include "renderer/frames.h"
#include "test_scale.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

// What a walk of a direct tree finds, checked on the way: leaves in depth-first order, inner nodes, depth.
struct Walk {
    std::vector<uint32_t> prims;  // leaf lanes' triangles in depth-first order
    std::vector<uint32_t> leaf_sizes;  // in depth-first order
    size_t inner = 0, leaves = 0;
    uint32_t depth = 0;
};

// Walks node `n`, checking that each child's box contains its subtree's triangles, that a leaf's count is the
// lanes it fills (the rest empty), that an inner child holds more than a block's triangles and a leaf at most
// that, and that a node has fewer than N children only when all of them are leaves. Returns the triangles below.
template <int N>
uint32_t walk(const WideBvh<N>& tree, std::span<const Triangle> tris, uint32_t n, uint32_t depth, Walk& out) {
    constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    const WideNode<N>& node = tree.nodes[n];
    out.depth = std::max(out.depth, depth);
    ++out.inner;
    uint32_t below = 0;
    int children = 0;
    bool all_leaves = true;
    for (int i = 0; i < N; ++i) {
        if (node.is_empty(i)) continue;
        ++children;
        const BBox box = tree.frame.box(node, i);
        const size_t first = out.prims.size();
        if (node.is_leaf(i)) {
            ++out.leaves;
            out.leaf_sizes.push_back(node.count[i]);
            const auto& block = tree.leaves[node.child[i]];
            REQUIRE(node.count[i] <= kLanes);
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                REQUIRE((lane < node.count[i]) == (block.prim[lane] != block.kNone));
                if (lane < node.count[i]) out.prims.push_back(block.prim[lane]);
            }
        } else {
            all_leaves = false;
            const uint32_t count = walk(tree, tris, node.child[i], depth + 1, out);
            REQUIRE(count > kLanes);
        }
        for (size_t k = first; k < out.prims.size(); ++k) {
            const BBox t = BBox::of(tris[out.prims[k]]);
            REQUIRE(box.contains(t.lower));
            REQUIRE(box.contains(t.upper));
        }
        below += uint32_t(out.prims.size() - first);
    }
    REQUIRE(children >= 1);
    if (children < N) REQUIRE(all_leaves);
    return below;
}

// The references in Morton order, as build_wide_lbvh sorts them.
std::vector<uint32_t> morton_prims(std::span<const Triangle> tris) {
    const std::vector<PrimRef> refs = make_prim_refs(tris);
    const MortonOrder sorted = sort_by_morton_code(refs);
    std::vector<uint32_t> prims;
    for (uint32_t i : sorted.order) prims.push_back(refs[i].prim);
    return prims;
}

// The leaves' sizes in depth-first order under the sorted codes [begin, end), by lbvh_direct.h's rules written
// plainly: the largest child split (the first of equals) at the first code with the highest differing bit set,
// found by a linear scan, or in the middle, until there are `width` children or all have at most `lanes`.
void plain_leaf_sizes(const std::vector<uint64_t>& codes, uint32_t begin, uint32_t end, size_t width, uint32_t lanes,
                      std::vector<uint32_t>& out) {
    std::vector<std::pair<uint32_t, uint32_t>> children{{begin, end}};
    const auto size = [](const std::pair<uint32_t, uint32_t>& c) { return c.second - c.first; };
    while (children.size() < width) {
        auto largest = std::max_element(children.begin(), children.end(), [&](const auto& a, const auto& b) { return size(a) < size(b); });
        if (size(*largest) <= lanes) break;
        const auto [b, e] = *largest;
        uint32_t middle = b + (e - b) / 2;
        if (codes[b] != codes[e - 1]) {
            const int bit = 63 - std::countl_zero(codes[b] ^ codes[e - 1]);
            for (middle = b; !(codes[middle] >> bit & 1); ++middle) {}
        }
        *largest = {b, middle};
        children.insert(largest + 1, {middle, e});
    }
    for (const auto& c : children) {
        if (size(c) <= lanes) out.push_back(size(c));
        else plain_leaf_sizes(codes, c.first, c.second, width, lanes, out);
    }
}

template <int N>
void check_structure(std::span<const Triangle> tris, const std::string& what) {
    if constexpr (kernel_compiled(N)) {
        INFO(what << ", bvh" << N);
        const WideBvh<N> tree = build_wide_lbvh<N>(BuildInput{tris, make_prim_refs(tris)});
        Walk found;
        walk(tree, tris, 0, 0, found);
        // Leaves are runs of the Morton order, in that order: every triangle once.
        CHECK(found.prims == morton_prims(tris));
        const std::vector<uint64_t> codes = sort_by_morton_code(make_prim_refs(tris)).codes;
        std::vector<uint32_t> sizes;
        plain_leaf_sizes(codes, 0, uint32_t(codes.size()), N, uint32_t(block_lanes(N)), sizes);
        CHECK(found.leaf_sizes == sizes);
        CHECK(found.inner == tree.nodes.size());
        CHECK(found.leaves == tree.leaves.size());
        CHECK(found.depth < kMaxBvhDepth);
    }
}

template <int N>
void check_thread_independence(std::span<const Triangle> tris, const std::string& what) {
    if constexpr (kernel_compiled(N)) {
        INFO(what << ", bvh" << N);
        const auto build = [&](int threads) {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
            return build_wide_lbvh<N>(BuildInput{tris, make_prim_refs(tris)});
        };
        const WideBvh<N> one = build(1), two = build(2);
        REQUIRE(one.nodes.size() == two.nodes.size());
        REQUIRE(one.leaves.size() == two.leaves.size());
        CHECK(std::memcmp(one.nodes.data(), two.nodes.data(), one.nodes.size() * sizeof(WideNode<N>)) == 0);
        CHECK(std::memcmp(one.leaves.data(), two.leaves.data(), one.leaves.size() * sizeof(one.leaves[0])) == 0);
    }
}

// `count` copies of one triangle turned about its centroid: every Morton code equal, so every split is a middle one.
std::vector<Triangle> one_centroid(size_t count) {
    std::vector<Triangle> tris;
    for (size_t i = 0; i < count; ++i) {
        const float a = 0.001f * float(i);
        const Vec3 u(std::cos(a), std::sin(a), 0.0f), v(-std::sin(a), std::cos(a), 0.3f);
        tris.push_back({u + v, -u, -v});  // centroid: (u + v - u - v) / 3 = 0
    }
    return tris;
}

}  // namespace

TEST_CASE("direct lbvh trees: Morton-ordered leaves of at most a block, full nodes above them", "[builders][direct]") {
    for (const char* spec : {"gen:cylinders?tris=30000&seed=5", "gen:box?tris=300&seed=6", "gen:foliage?tris=5000&seed=2"}) {
        const std::vector<Triangle> tris = flatten(load_scene(spec)).triangles;
        check_structure<4>(tris, spec);
        check_structure<8>(tris, spec);
    }
    // Equal codes split in the middle: a balanced tree, not a chain of 20,000 levels.
    const std::vector<Triangle> same = one_centroid(20000);
    check_structure<8>(same, "one centroid");
    // 1, 8 (one leaf under the root), 9 (two leaves) and 65 triangles (an inner child).
    const std::vector<Triangle> box = flatten(load_scene("gen:box?tris=400&seed=1")).triangles;
    for (size_t n : {1, 8, 9, 65}) {
        const std::vector<Triangle> few(box.begin(), box.begin() + n);
        check_structure<4>(few, std::to_string(n) + " triangles");
        check_structure<8>(few, std::to_string(n) + " triangles");
    }
    if constexpr (kernel_compiled(8)) {
        const std::vector<Triangle> few(box.begin(), box.begin() + 8);
        const WideBvh<8> root_leaf = build_wide_lbvh<8>(BuildInput{few, make_prim_refs(few)});
        REQUIRE(root_leaf.nodes.size() == 1);
        CHECK(root_leaf.nodes[0].count[0] == 8);
        CHECK(root_leaf.nodes[0].is_empty(1));
        CHECK(build_wide_lbvh<8>(BuildInput{{}, {}}).nodes.empty());
    }
}

TEST_CASE("direct lbvh trees are the same with 1 and 2 threads", "[builders][direct]") {
    // Large enough for the concurrent top levels, and small enough for the serial path alone.
    for (const char* spec : {"gen:cylinders?tris=40000&seed=5", "gen:box?tris=300&seed=6"}) {
        const std::vector<Triangle> tris = flatten(load_scene(spec)).triangles;
        check_thread_independence<4>(tris, spec);
        check_thread_independence<8>(tris, spec);
    }
}

TEST_CASE("direct lbvh trees agree with brute force at scales 1e-12 to 1e12, far from the origin", "[builders][direct][extreme]") {
    for (const float scale : {1.0f, 1e-12f, 1e12f})
        for (const char* spec : {"gen:box?tris=3000&seed=4", "gen:cylinders?tris=2000&seed=6"}) {
            const std::string what = std::string(spec) + " scaled by " + std::to_string(scale);
            const std::vector<Triangle> tris = scaled_far_from_origin(flatten(load_scene(spec)).triangles, scale);
            std::vector<Ray> rays = random_rays(tris, 3000, 13);
            const std::vector<Ray> corners = corner_and_edge_rays(tris, 1000, scale);
            rays.insert(rays.end(), corners.begin(), corners.end());
            const std::vector<Hit> expected = brute_force_all(tris, rays);
            const BuiltScene direct = build_direct(tris);  // the kernels keep references to its trees
            for (const KernelUnderTest& kernel : kernels_of(direct)) {
                std::vector<Hit> actual(rays.size());
                size_t any_mismatches = 0;
                for (size_t i = 0; i < rays.size(); ++i) {
                    actual[i] = kernel.closest(rays[i]);
                    any_mismatches += kernel.any(rays[i]) != expected[i].found();
                }
                CHECK(count_mismatches(rays, expected, actual, what + " / " + kernel.name) == 0);
                CHECK(any_mismatches == 0);
            }
        }
}

TEST_CASE("the accelerator's direct collapse: lbvh's tree, flat, bvh4 or bvh8; its batches answer as brute force", "[builders][direct]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=9"));
    const std::vector<Ray> rays = random_rays(flat.triangles, 2000, 3);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const char* kernel : {"bvh4", "bvh8"}) {
        if (!kernel_compiled(kernel_width(kernel)) || !cpu_runs(kernel_width(kernel))) continue;
        CanopyOptions options{"lbvh", "", kernel};
        options.collapse = CollapseMethod::Direct;
        const auto accel = make_canopy_accelerator(flat, options);
        accel->prepare();
        accel->build();
        CHECK(accel->kernel() == std::string(kernel) + " direct");
        std::vector<Hit> single(rays.size()), batch(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) single[i] = accel->trace(rays[i]);
        accel->trace_batch(Query::Closest, rays, batch);
        CHECK(count_mismatches(rays, expected, single, std::string(kernel) + " direct") == 0);
        CHECK(count_mismatches(rays, expected, batch, std::string(kernel) + " direct, batch") == 0);
        // No binary tree: its metrics are absent, the layout's are there.
        const AcceleratorReport report = accel->report(true);
        CHECK_FALSE(report.sah);
        CHECK(report.layout_sah.value_or(0.0) > 0.0);
        CHECK(report.layout_epo.value_or(0.0) > 0.0);
    }
    for (const auto& [builder, kernel] : {std::pair{"binned", "bvh8"}, std::pair{"lbvh", "bvh2"}}) {
        CanopyOptions options{builder, "", kernel};
        options.collapse = CollapseMethod::Direct;
        CHECK_THROWS_WITH(make_canopy_accelerator(flat, options), Catch::Contains("collapse 'direct' is lbvh's wide tree"));
    }
    CHECK_THROWS_AS(collapse<8>(Bvh{}, flat.triangles, CollapseMethod::Direct), std::invalid_argument);
}

TEST_CASE("lbvh's flat wide trees are direct unless a collapse is asked for; other trees take the optimal collapse", "[builders][direct]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=500&seed=2"));
    const auto collapse_for = [](const char* builder, const char* kernel, std::optional<CollapseMethod> collapse = {},
                                const char* toplevel = "flat") {
        CanopyOptions options{builder, "", kernel};
        options.toplevel = toplevel, options.collapse = collapse;
        return collapse_of(options);
    };
    CHECK(collapse_for("lbvh", "bvh8") == CollapseMethod::Direct);
    CHECK(collapse_for("lbvh", "bvh4") == CollapseMethod::Direct);
    CHECK(collapse_for("lbvh", "bvh2") == CollapseMethod::Optimal);
    CHECK(collapse_for("lbvh", "bvh8", {}, "two-level") == CollapseMethod::Optimal);
    CHECK(collapse_for("lbvh", "bvh8", CollapseMethod::Optimal) == CollapseMethod::Optimal);
    CHECK(collapse_for("lbvh", "bvh8", CollapseMethod::Greedy) == CollapseMethod::Greedy);
    CHECK(collapse_for("binned", "bvh8") == CollapseMethod::Optimal);
    CHECK(collapse_for("bittner", "bvh8") == CollapseMethod::Optimal);  // its start tree is lbvh's binary tree
    if (!kernel_compiled(8) || !cpu_runs(8)) return;
    // The accelerator builds what collapse_of says and names it.
    for (const auto& [collapse, name] : {std::pair{std::optional<CollapseMethod>{}, "bvh8 direct"},
                                         std::pair{std::optional{CollapseMethod::Optimal}, "bvh8"}}) {
        CanopyOptions options{"lbvh", "", "bvh8"};
        options.collapse = collapse;
        const auto accel = make_canopy_accelerator(flat, options);
        accel->prepare();
        accel->build();
        CHECK(accel->kernel() == name);
        CHECK(accel->report(false).sah.has_value() == collapse.has_value());  // the direct tree has no binary tree
    }
}
