// Clustering builders (agglo, ploc) and LBVH's SAH leaf collapse: behaviour the registry-wide tests do not pin.
#include "oracle.h"

#include "accel/cluster_tree.h"
#include "accel/builders/lbvh_sah.h"
#include "accel/morton.h"
#include "accel/builders/ploc.h"

#include <numeric>
#include <stdexcept>

using namespace canopy;
using namespace canopy::test;

namespace {

Bvh build(const char* builder, std::span<const Triangle> tris, const BuildSettings& settings = {}) {
    return find_builder(builder).build(BuildInput{tris, make_prim_refs(tris)}, settings);
}

// Every triangle in exactly one leaf, every child box inside its parent's; returns the depth.
uint32_t check_tree(const Bvh& bvh, size_t triangles, uint32_t max_leaf) {
    std::vector<uint32_t> seen(triangles, 0);
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
    uint32_t depth = 0;
    size_t reached = 0;
    while (!stack.empty()) {
        const auto [index, d] = stack.back();
        stack.pop_back();
        ++reached;
        depth = std::max(depth, d);
        const BvhNode& node = bvh.nodes[index];
        if (node.is_leaf()) {
            CHECK(node.count <= max_leaf);
            for (uint32_t i = node.index; i < node.index + node.count; ++i) ++seen[bvh.refs[i]];
            continue;
        }
        for (uint32_t c = 0; c < 2; ++c) {
            const BBox& child = bvh.nodes[node.index + c].bounds;
            CHECK(glm::all(glm::lessThanEqual(node.bounds.lower, child.lower)));
            CHECK(glm::all(glm::greaterThanEqual(node.bounds.upper, child.upper)));
            stack.push_back({node.index + c, d + 1});
        }
    }
    CHECK(reached == bvh.nodes.size());
    CHECK(std::count(seen.begin(), seen.end(), 1u) == std::ptrdiff_t(triangles));
    return depth;
}

Triangle small_triangle_at(float x) { return {Vec3(x, 0, 0), Vec3(x + 0.5f, 0, 0), Vec3(x, 0.5f, 0)}; }

// 63-bit Morton codes of the references' centroids in their bounds, interleaved bit by bit (x highest).
std::vector<uint64_t> reference_codes(const std::vector<PrimRef>& refs) {
    BBox centroids;
    for (const PrimRef& r : refs) centroids.extend(r.center2());
    const Vec3 extent = centroids.extent();
    Vec3 scale;
    for (int a = 0; a < 3; ++a) scale[a] = extent[a] > 0 ? float((1u << 21) - 1) / extent[a] : 0.0f;
    std::vector<uint64_t> codes;
    for (const PrimRef& r : refs) {
        const Vec3 q = (r.center2() - centroids.lower) * scale;
        const uint64_t cell[3] = {uint64_t(q.x), uint64_t(q.y), uint64_t(q.z)};
        uint64_t code = 0;
        for (int bit = 0; bit < 21; ++bit)
            for (int a = 0; a < 3; ++a) code |= (cell[a] >> bit & 1) << (3 * bit + 2 - a);
        codes.push_back(code);
    }
    return codes;
}

}  // namespace

TEST_CASE("Morton order is a stable sort of the centroids' codes", "[builders][clustering]") {
    // A spread-out surface, large enough that the sort splits it into chunks, plus clusters that tie in the
    // radix-sorted top bits: short runs, one long run of distinct codes (a cloud of tiny triangles), and identical
    // centroids (equal codes keep index order).
    std::vector<Triangle> tris = flatten(load_scene("gen:surface?tris=100000&seed=3")).triangles;
    for (int i = 0; i < 500; ++i) {
        const Vec3 p(0.1f + 1e-6f * float(i % 37), 0.2f + 1e-6f * float(i % 11), 0.3f + 1e-6f * float(i % 5));
        tris.push_back({p, p + Vec3(1e-7f, 0, 0), p + Vec3(0, 1e-7f, 0)});
    }
    for (int i = 0; i < 40; ++i) tris.push_back(small_triangle_at(0.25f));
    const std::vector<PrimRef> refs = make_prim_refs(tris);
    const std::vector<uint64_t> codes = reference_codes(refs);
    std::vector<uint32_t> expected(refs.size());
    std::iota(expected.begin(), expected.end(), 0u);
    std::stable_sort(expected.begin(), expected.end(), [&](uint32_t a, uint32_t b) { return codes[a] < codes[b]; });

    const MortonOrder sorted = sort_by_morton_code(refs);
    CHECK(sorted.order == expected);
    size_t wrong_codes = 0;
    for (size_t i = 0; i < expected.size(); ++i) wrong_codes += sorted.codes[i] != codes[expected[i]];
    CHECK(wrong_codes == 0);
}

TEST_CASE("agglomerative clustering merges the closest pairs first", "[builders][clustering]") {
    // Two pairs far apart: each pair must be a subtree, whatever the input order.
    const std::vector<Triangle> tris{small_triangle_at(10), small_triangle_at(0), small_triangle_at(11), small_triangle_at(1)};
    const Bvh bvh = build("agglo", tris);
    REQUIRE(bvh.nodes.size() == 7);
    for (uint32_t c = 0; c < 2; ++c) {
        const BvhNode& pair = bvh.nodes[bvh.nodes[0].index + c];
        REQUIRE(!pair.is_leaf());
        const uint32_t a = bvh.refs[bvh.nodes[pair.index].index], b = bvh.refs[bvh.nodes[pair.index + 1].index];
        CHECK(std::min(a, b) + 2 == std::max(a, b));  // {0, 2} (x = 10, 11) or {1, 3} (x = 0, 1)
    }
}

TEST_CASE("clustering builds trees of lower SAH than LBVH", "[builders][clustering]") {
    const FlatScene flat = flatten(load_scene("gen:cylinders?tris=4000&seed=11"));
    const double lbvh = sah_cost(build("lbvh", flat.triangles));
    for (const char* builder : {"agglo", "ploc"}) {
        INFO(builder);
        const Bvh bvh = build(builder, flat.triangles);
        check_tree(bvh, flat.triangles.size(), 1);
        CHECK(sah_cost(bvh) < 0.9 * lbvh);
    }
}

TEST_CASE("ploc is valid with any search radius and rejects radius 0", "[builders][clustering]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=12"));
    Bvh narrow = build_ploc(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, BuildSettings{}, 1);
    Bvh wide = build_ploc(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, BuildSettings{}, 16);
    check_tree(narrow, flat.triangles.size(), 1);
    check_tree(wide, flat.triangles.size(), 1);
    CHECK(narrow.refs != wide.refs);  // a wider window finds other neighbours
    CHECK_THROWS_AS(build_ploc(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, BuildSettings{}, 0),
                    std::invalid_argument);
}

TEST_CASE("lbvh-sah collapses leaves only where SAH gains", "[builders][clustering]") {
    const FlatScene flat = flatten(load_scene("gen:surface?tris=5000&seed=13"));
    BuildSettings settings;
    settings.max_leaf_size = 4;
    const Bvh lbvh = build("lbvh", flat.triangles, settings);
    const Bvh collapsed = build_lbvh_sah(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, settings);
    check_tree(collapsed, flat.triangles.size(), 4);
    CHECK(collapsed.nodes.size() < lbvh.nodes.size());
    CHECK(sah_cost(collapsed) <= sah_cost(lbvh) * (1 + 1e-6));  // up to rounding: each collapse lowers it
    CHECK(collapsed.refs == lbvh.refs);  // leaves take their subtree's refs in place
}

TEST_CASE("a merge chain deeper than the limit is rebuilt by median splits", "[builders][clustering]") {
    std::vector<Triangle> tris;
    for (int i = 0; i < 300; ++i) tris.push_back(small_triangle_at(float(i)));
    const std::vector<PrimRef> refs = make_prim_refs(tris);
    ClusterTree tree(refs);
    uint32_t chain = 0;
    for (uint32_t i = 1; i < 300; ++i) chain = tree.merge(chain, i);  // depth 299
    const Bvh bvh = tree.to_bvh(refs);
    const uint32_t depth = check_tree(bvh, tris.size(), 1);
    CHECK(depth <= kMaxBvhDepth);
    CHECK(depth >= kMedianFallbackDepth);  // the chain is kept down to where the median split starts
}
