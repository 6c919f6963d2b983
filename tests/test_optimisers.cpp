// Tree optimisers: never worse by SAH than their start trees, deterministic, and usable on any start tree.
#include "oracle.h"

#include "accel/builders/treelet_restructuring.h"

#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

Bvh build(const std::string& builder, std::span<const Triangle> tris, const BuildSettings& settings) {
    return find_builder(builder).build(BuildInput{tris, make_prim_refs(tris)}, settings);
}

bool same_tree(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.refs == b.refs &&
           std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)) == 0;
}

// The registered optimisers: a new one is tested here by its registry entry alone.
std::vector<std::string> optimisers() {
    std::vector<std::string> names;
    for (const BuilderEntry& entry : builders())
        if (entry.optimiser()) names.push_back(entry.name);
    return names;
}

}  // namespace

TEST_CASE("optimisers never raise the SAH of their start tree", "[optimisers]") {
    for (const char* spec : {"gen:box?tris=3000&seed=2", "gen:cylinders?tris=3000&seed=5"}) {
        const FlatScene flat = flatten(load_scene(spec));
        for (const char* start : {"lbvh", "binned", "sweep"}) {
            BuildSettings settings;
            const double start_sah = sah_cost(build(start, flat.triangles, settings));
            settings.start = start;
            for (const std::string& optimiser : optimisers()) {
                INFO(spec << " / " << optimiser << " from " << start);
                const double sah = sah_cost(build(optimiser, flat.triangles, settings));
                CHECK(sah <= start_sah);
            }
        }
    }
}

TEST_CASE("optimisers improve an LBVH substantially", "[optimisers]") {
    // LBVH's single-triangle leaves and spatial-median splits leave much to gain (the quality-metrics paper,
    // Table 1: every optimiser is far below LBVH).
    const FlatScene flat = flatten(load_scene("gen:cylinders?tris=3000&seed=5"));
    const double lbvh = sah_cost(build("lbvh", flat.triangles, {}));
    REQUIRE(optimisers().size() >= 4);  // bittner, hillclimb, anneal, treelet
    for (const std::string& optimiser : optimisers()) {
        INFO(optimiser);
        CHECK(sah_cost(build(optimiser, flat.triangles, {})) < 0.9 * lbvh);
    }
}

TEST_CASE("annealing gives the same tree on every run", "[optimisers]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=2"));
    CHECK(same_tree(build("anneal", flat.triangles, {}), build("anneal", flat.triangles, {})));
}

TEST_CASE("treelet optimisation applies to a given tree and respects the leaf size", "[optimisers]") {
    const FlatScene flat = flatten(load_scene("gen:surface?tris=3000&seed=9"));
    BuildSettings settings;
    settings.max_leaf_size = 3;
    Bvh bvh = build("sweep", flat.triangles, settings);
    const double before = sah_cost(bvh);
    optimise_treelets(bvh, settings);
    CHECK(sah_cost(bvh) <= before);
    CHECK(tree_stats(bvh, flat.triangles.size()).max_leaf_size <= 3);
    CHECK(bvh.refs.size() == flat.triangles.size());
}
