// Structural invariants of every builder's trees, SAH by eq. 1, thread-count independence.
#include "oracle.h"
#include "engine/accelerator.h"
#include "test_scale.h"

#include <tbb/global_control.h>

#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

void check_invariants(const Bvh& bvh, std::span<const Triangle> tris, const std::string& what) {
    INFO(what);
    REQUIRE(!bvh.nodes.empty());
    std::vector<uint32_t> seen(tris.size(), 0);
    const bool splits = bvh.refs.size() > tris.size();
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
    size_t reached = 0, bad_bounds = 0;
    uint32_t depth = 0;
    while (!stack.empty()) {
        const auto [index, d] = stack.back();
        stack.pop_back();
        ++reached;
        depth = std::max(depth, d);
        const BvhNode& node = bvh.nodes[index];
        auto inside = [&](const BBox& b) {
            return glm::all(glm::lessThanEqual(node.bounds.lower, b.lower)) &&
                   glm::all(glm::greaterThanEqual(node.bounds.upper, b.upper));
        };
        auto overlaps = [&](const BBox& b) {
            return glm::all(glm::lessThanEqual(node.bounds.lower, b.upper)) &&
                   glm::all(glm::greaterThanEqual(node.bounds.upper, b.lower));
        };
        if (node.is_leaf()) {
            CHECK(node.count <= BuildSettings{}.max_leaf_size);
            for (uint32_t i = node.index; i < node.index + node.count; ++i) {
                ++seen[bvh.refs[i]];
                // A split builder's leaf holds a piece of the triangle: its box must at least meet the
                // triangle's (the oracle tests check the pieces cover it). Without splits it holds all of it.
                bad_bounds += splits ? !overlaps(BBox::of(tris[bvh.refs[i]])) : !inside(BBox::of(tris[bvh.refs[i]]));
            }
        } else {
            for (uint32_t c = 0; c < 2; ++c) {
                bad_bounds += !inside(bvh.nodes[node.index + c].bounds);
                stack.push_back({node.index + c, d + 1});
            }
        }
    }
    CHECK(reached == bvh.nodes.size());  // dense: no unreachable nodes
    CHECK(bad_bounds == 0);
    CHECK(depth <= kMaxBvhDepth);
    CHECK(std::count(seen.begin(), seen.end(), 0u) == 0);  // every triangle referenced
}

}  // namespace

TEST_CASE("every builder's tree is well formed", "[builders]") {
    for (const std::string& spec : {scaled_spec("box", 20000, 1), scaled_spec("cylinders", 20000, 2), scaled_spec("triangles", 5000, 3)}) {
        const FlatScene flat = flatten(load_scene(spec));
        for (const BuilderEntry& builder : builders()) {
            const BuiltScene built = build_with(builder.name, flat.triangles);
            check_invariants(built.binary, flat.triangles, spec + " / " + builder.name);
            const TreeStats stats = tree_stats(built.binary, flat.triangles.size());
            CHECK(stats.refs_per_triangle >= 1.0);
            CHECK(built.bvh2.nodes.size() == stats.inner_nodes);
            CHECK(built.bvh2.leaves.size() == stats.references);
        }
    }
}

// Far out (1e25) and large (1e22), box areas overflow float: every SAH and distance is infinite. Builders may then
// build poor trees, but well-formed ones, and never crash.
TEST_CASE("every builder's tree is well formed where box areas overflow float", "[builders][extreme]") {
    std::vector<Triangle> tris = flatten(load_scene("gen:box?tris=2000&seed=17")).triangles;
    for (Triangle& t : tris)
        for (Vec3* v : {&t.v0, &t.v1, &t.v2}) *v = *v * 1e22f + Vec3(3e24f, 1e25f, -2e25f);
    for (const BuilderEntry& builder : builders()) check_invariants(build_with(builder.name, tris).binary, tris, builder.name);
}

TEST_CASE("binned SAH references each triangle once", "[builders]") {
    const FlatScene flat = flatten(load_scene("gen:surface?tris=10000&seed=4"));
    const BuiltScene built = build_with("binned", flat.triangles);
    CHECK(tree_stats(built.binary, flat.triangles.size()).refs_per_triangle == 1.0);
}

TEST_CASE("pathological inputs keep trees within the depth limit", "[builders]") {
    std::vector<Triangle> tris;
    // Triangles at exponentially growing distances (120 scales): every SAH split peels off very few.
    const int copies = int(scaled(3000, 600));
    for (int i = 0; i < copies; ++i) {
        const float x = std::ldexp(1.0f, i % 120 - 60);
        tris.push_back({Vec3(x, 0, 0), Vec3(x * 1.001f, x * 1e-3f, 0), Vec3(x, 0, x * 1e-3f)});
    }
    // Many triangles with one centroid.
    for (int i = 0; i < copies; ++i) tris.push_back({Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, float(i % 7), 0)});
    for (const BuilderEntry& builder : builders()) {
        const BuiltScene built = build_with(builder.name, tris);
        check_invariants(built.binary, tris, builder.name);
    }
    check_against_oracle(tris, random_rays(tris, scaled(5000, 500), 3), "pathological");
}

TEST_CASE("a single triangle and a leaf root are traced", "[builders]") {
    const std::vector<Triangle> one{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}};
    const BuiltScene built = build_with("binned", one);
    REQUIRE(built.binary.nodes.size() == 1);
    Hit hit;
    CHECK(closest_hit(built.bvh2, Ray{{0.25f, 0.25f, 1.0f}, {0, 0, -1}}, hit));
    CHECK(hit.t == Approx(1.0f));
    CHECK(!closest_hit(built.bvh2, Ray{{2.0f, 2.0f, 1.0f}, {0, 0, -1}}, hit));
}

TEST_CASE("SAH follows eq. 1 of the quality-metrics paper", "[metrics]") {
    // Root [0,2]^3 (half area 12) over leaves [0,1]^3 with 1 triangle and [1,2]^3 with 2 (half area 3 each):
    // (1.2 * 12 + 1.0 * (1 * 3 + 2 * 3)) / 12 = 1.95
    Bvh bvh;
    bvh.nodes = {{{Vec3(0), Vec3(2)}, 1, 0}, {{Vec3(0), Vec3(1)}, 0, 1}, {{Vec3(1), Vec3(2)}, 1, 2}};
    bvh.refs = {0, 1, 2};
    CHECK(sah_cost(bvh) == Approx(1.95));
    CHECK(sah_cost(bvh, {2.0f, 0.5f}) == Approx((2.0 * 12 + 0.5 * 9) / 12));
    const TreeStats stats = tree_stats(bvh, 3);
    CHECK(stats.leaves == 2);
    CHECK(stats.inner_nodes == 1);
    CHECK(stats.depth == 1);
    CHECK(stats.refs_per_triangle == 1.0);
}

TEST_CASE("the tree is the same with 1 and 2 threads", "[builders]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("cylinders", 60000, 7)));
    for (const BuilderEntry& builder : builders()) {
        Bvh one, two;
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
            one = build_with(builder.name, flat.triangles).binary;
        }
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
            two = build_with(builder.name, flat.triangles).binary;
        }
        INFO(builder.name);
        REQUIRE(one.nodes.size() == two.nodes.size());
        CHECK(std::memcmp(one.nodes.data(), two.nodes.data(), one.nodes.size() * sizeof(BvhNode)) == 0);
        CHECK(one.refs == two.refs);
    }
}

namespace {

// A toy builder registered from this file alone: binned SAH with its leaf size limit as a parameter, "leaf" (1 to
// 64). What a parameterised builder's own files hold, in a few lines: its parameter parsed, checked and used.
uint32_t toy_leaf(const std::string& text) {
    size_t used = 0;
    int leaf = 0;
    try {
        leaf = std::stoi(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (text.empty() || used != text.size() || leaf < 1 || leaf > 64)
        throw std::invalid_argument("toy leaf '" + text + "': a whole number from 1 to 64");
    return uint32_t(leaf);
}

Bvh build_toy(BuildInput&& input, const BuildSettings& settings) {
    BuildSettings capped = settings;
    const std::string* leaf = settings.params.find("leaf");
    capped.max_leaf_size = toy_leaf(leaf ? *leaf : "8");
    capped.costs.inner *= 100.0f;  // leaves as large as the limit allows, so the limit shows
    return find_builder("binned").build(std::move(input), capped);
}

BuilderEntry toy_entry() {
    return {"toy", "binned SAH with a leaf size parameter (a test's)", &build_toy, nullptr,
            {{"leaf", "8", "triangles a leaf holds at most", [](const std::string& text) { return std::to_string(toy_leaf(text)); }}},
            1.5};
}

uint32_t largest_leaf(const Bvh& bvh) {
    uint32_t largest = 0;
    for (const BvhNode& node : bvh.nodes)
        if (node.is_leaf()) largest = std::max(largest, node.count);
    return largest;
}

}  // namespace

TEST_CASE("a builder registered from a test file is listed, takes its parameter and is traced right", "[builders]") {
    const BuilderRegistration toy = register_builder(toy_entry());
    CHECK(is_bvh_builder("toy"));
    const std::vector<BuilderName> names = all_builders();
    CHECK(std::any_of(names.begin(), names.end(), [](const BuilderName& b) { return b.name == "toy" && b.description.find("leaf size") != std::string::npos; }));
    CHECK_FALSE(find_builder("toy").optimiser());
    CHECK(reference_cap_per_triangle("toy") == 1.5);
    CHECK(builder_params_help(find_builder("toy")).find("toy:leaf=... (default 8)") != std::string::npos);
    CHECK_THROWS_WITH(register_builder(toy_entry()), Catch::Contains("registered already"));

    // Its parameter parses; unknown keys and bad values are refused, naming the builder, the key and the known ones.
    const BuilderSpec spec = parse_builder_spec("toy:leaf=2");
    CHECK(spec.name == "toy");
    REQUIRE(spec.params.find("leaf"));
    CHECK(*spec.params.find("leaf") == "2");
    CHECK(spec.text() == "toy:leaf=2");
    CHECK(parse_builder_spec("toy:leaf=08").text() == "toy");  // the default, spelt otherwise
    CHECK_THROWS_WITH(parse_builder_spec("toy:size=2"), Catch::Contains("builder 'toy' has no parameter 'size' (known: leaf)"));
    CHECK_THROWS_WITH(parse_builder_spec("toy:leaf=0"), Catch::Contains("toy leaf '0'"));
    CHECK_THROWS_WITH(parse_builder_spec("toy:leaf"), Catch::Contains("no key=value"));
    CHECK_THROWS_WITH(parse_builder_spec("toy:leaf=2,leaf=3"), Catch::Contains("given twice"));
    CHECK_THROWS_WITH(parse_builder_spec("binned:leaf=2"), Catch::Contains("builder 'binned' has no parameter 'leaf' (it takes none)"));
    CHECK(join_builder_specs({"toy:leaf=2", "binned", "esc:sa_max=8x", "binned"}) ==
          std::vector<std::string>{"toy:leaf=2", "binned", "esc:sa_max=8x", "binned"});

    // The parameter reaches the build, and the accelerator built by the toy answers as brute force does.
    const FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=4"));
    BuildSettings two;
    two.params = spec.params;
    CHECK(largest_leaf(find_builder("toy").build(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, two)) <= 2);
    CHECK(largest_leaf(find_builder("toy").build(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, {})) > 2);
    const std::vector<Ray> rays = random_rays(flat.triangles, 2000, 6);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const char* kernel : {"bvh2", "auto"}) {
        const auto accel = make_canopy_accelerator(flat, {"toy:leaf=2", "", kernel});
        CHECK(accel->builder() == "toy:leaf=2");
        accel->prepare();
        accel->build();
        std::vector<Hit> hits;
        for (const Ray& ray : rays) hits.push_back(accel->trace(ray));
        CHECK(count_mismatches(rays, expected, hits, std::string("toy ") + kernel) == 0);
    }
}

TEST_CASE("a registered builder leaves the registry with its registration", "[builders]") {
    {
        const BuilderRegistration toy = register_builder(toy_entry());
        CHECK(is_bvh_builder("toy"));
    }
    CHECK_FALSE(is_bvh_builder("toy"));
    CHECK_THROWS_WITH(parse_builder_spec("toy:leaf=2"), Catch::Contains("unknown builder 'toy'"));
    CHECK_THROWS_WITH(register_builder(BuilderEntry{"to:y", "", &build_toy}), Catch::Contains("without ':' or ','"));
}

TEST_CASE("builder specs split from a comma list keep their parameters together", "[builders]") {
    CHECK(join_builder_specs({"esc:sa_max=8x", "binned", "sbvh:alpha=1e-5", "lbvh"}) ==
          std::vector<std::string>{"esc:sa_max=8x", "binned", "sbvh:alpha=1e-5", "lbvh"});
    const BuilderSpec esc = parse_builder_spec("esc:sa_max=8x");
    CHECK(esc.text() == "esc:sa_max=8x");
    CHECK(parse_builder_spec("esc:sa_max=auto").text() == "esc");
    CHECK_THROWS_WITH(parse_builder_spec("esc:sa_max=8x,alpha=1"), Catch::Contains("builder 'esc' has no parameter 'alpha' (known: sa_max)"));
    CHECK_THROWS_WITH(parse_builder_spec("esc:sa_max=-2x"), Catch::Contains("SA_max '-2x'"));
}
