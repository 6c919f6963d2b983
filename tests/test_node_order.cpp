// The node-order experiment (study --permute-nodes, Aila et al. 2013 sec. 6): a permuted tree is the same tree in
// another memory order, so every query answers exactly as before.
#include "oracle.h"
#include "renderer/frames.h"

#include <cstring>

using namespace canopy;
using canopy::test::random_rays;

namespace {

template <int N>
bool same_node(const WideNode<N>& a, const WideNode<N>& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

bool same_hit(const Hit& a, const Hit& b) {
    return a.prim == b.prim && std::memcmp(&a.t, &b.t, sizeof a.t) == 0 && std::memcmp(&a.u, &b.u, sizeof a.u) == 0 &&
           std::memcmp(&a.v, &b.v, sizeof a.v) == 0;
}

}  // namespace

TEST_CASE("permuting nodes keeps the root first, moves the others and re-points their parents", "[collapse]") {
    const FlatScene flat = flatten(load_scene("gen:cylinders?tris=20000&seed=3"));
    const Bvh bvh = find_builder("binned").build(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, BuildSettings{});
    const WideBvh<8> wide = collapse<8>(bvh, flat.triangles);
    WideBvh<8> permuted = wide;
    permute_nodes(permuted, 7);
    REQUIRE(permuted.nodes.size() == wide.nodes.size());
    REQUIRE(wide.nodes.size() > 100);
    // Same root box and leaves; few nodes keep their place.
    CHECK(std::memcmp(permuted.nodes[0].planes, wide.nodes[0].planes, sizeof wide.nodes[0].planes) == 0);
    size_t unmoved = 0;
    for (size_t i = 1; i < wide.nodes.size(); ++i) unmoved += same_node(wide.nodes[i], permuted.nodes[i]);
    CHECK(unmoved < wide.nodes.size() / 10);
    // Walking both trees together from the root meets the same node contents, children re-pointed.
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
    size_t visited = 0;
    while (!stack.empty()) {
        const auto [a, b] = stack.back();
        stack.pop_back();
        ++visited;
        const WideNode<8>& x = wide.nodes[a];
        const WideNode<8>& y = permuted.nodes[b];
        REQUIRE(std::memcmp(x.planes, y.planes, sizeof x.planes) == 0);
        for (int i = 0; i < 8; ++i) {
            REQUIRE(x.count[i] == y.count[i]);
            REQUIRE(x.is_empty(i) == y.is_empty(i));
            if (x.is_empty(i)) continue;
            if (x.is_leaf(i)) REQUIRE(x.child[i] == y.child[i]);
            else stack.push_back({x.child[i], y.child[i]});
        }
    }
    CHECK(visited == wide.nodes.size());
}

TEST_CASE("a permuted tree answers every ray as the original, at every width", "[collapse][oracle]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=5000&seed=4"));
    const std::vector<Ray> rays = random_rays(flat.triangles, 20000, 11);
    for (const char* kernel : {"bvh2", "bvh4", "bvh8"}) {
        CanopyOptions options{"sweep", "", kernel};
        auto original = make_canopy_accelerator(flat, options);
        options.permute_nodes = 12345;
        auto permuted = make_canopy_accelerator(flat, options);
        for (Accelerator* a : {original.get(), permuted.get()}) a->prepare(), a->build();
        CHECK(permuted->kernel() == original->kernel() + " permuted");
        size_t different = 0, counts_differ = 0;
        for (const Ray& ray : rays) {
            different += !same_hit(original->trace(ray), permuted->trace(ray));
            const TraversalCounts c = original->count(ray), d = permuted->count(ray);
            counts_differ += c.inner_nodes != d.inner_nodes || c.leaf_nodes != d.leaf_nodes;
        }
        INFO(kernel);
        CHECK(different == 0);
        CHECK(counts_differ == 0);
    }
}

TEST_CASE("permuted nodes are refused for a two-level top level, which they would not reach", "[collapse]") {
    const Scene scene = load_scene("gen:box?tris=500&seed=1");
    const FlatScene flat = flatten(scene);
    CanopyOptions options{"binned", "", "bvh8"};
    options.toplevel = "two-level";
    options.permute_nodes = 1;
    CHECK_THROWS_WITH(make_canopy_accelerator(scene, flat, options), Catch::Contains("flat trees only"));
}
