// Kernel dispatch and the counting variant of traversal.
#include "oracle.h"

using namespace canopy;
using namespace canopy::test;

TEST_CASE("kernel dispatch picks the widest kernel and names what is missing", "[kernels]") {
    const int widest = kernel_width("auto");
    for (const KernelInfo& k : kernel_infos())
        if (kernel_compiled(k.width) && cpu_runs(k.width)) CHECK(widest >= k.width);
    CHECK(kernel_width("bvh2") == 2);
    CHECK_THROWS_WITH(kernel_width("bvh3"), Catch::Contains("unknown kernel 'bvh3'"));
    for (const KernelInfo& k : kernel_infos())
        if (!kernel_compiled(k.width) || !cpu_runs(k.width)) CHECK_THROWS_WITH(kernel_width(k.name), Catch::Contains(k.isa));
}

template <int N>
void check_counts(const WideBvh<N>& bvh) {
    if constexpr (kernel_compiled(N)) {
        INFO("width " << N);
        TraversalCounts miss;
        Hit hit;
        CHECK(!traverse<Query::Closest>(bvh, Ray{{0, 0, 5}, {0, 0, 1}}, hit, miss));  // away from the root box
        CHECK(miss.inner_nodes == 1);
        CHECK(miss.leaf_nodes == 0);
        CHECK(miss.triangle_tests == 0);

        TraversalCounts counted;
        Hit counted_hit, plain_hit;
        const Ray down{{0.25f, 0.25f, 1.0f}, {0, 0, -1}};
        CHECK(traverse<Query::Closest>(bvh, down, counted_hit, counted));
        CHECK(closest_hit(bvh, down, plain_hit));
        CHECK(counted_hit.prim == plain_hit.prim);
        CHECK(counted.inner_nodes >= 1);
        CHECK(counted.leaf_nodes >= 1);
        CHECK(counted.triangle_tests >= counted.leaf_nodes);
    }
}

TEST_CASE("the counting variant counts visits and finds the same hits", "[kernels]") {
    // Two triangles in z = 0 and one far away: one leaf or more, counted per visit.
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},
                                     {Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)},
                                     {Vec3(-3, -3, -1), Vec3(-2, -3, -1), Vec3(-3, -2, -1)}};
    const BuiltScene built = build_with("binned", tris);
    check_counts(built.bvh2);
    check_counts(built.bvh4);
    check_counts(built.bvh8);

    const FlatScene flat = flatten(load_scene("gen:box?tris=5000&seed=2"));
    const BuiltScene box = build_with("binned", flat.triangles);
    TraversalCounts total;
    for (const Ray& ray : random_rays(flat.triangles, 1000, 3)) {
        Hit hit;
        traverse<Query::Closest>(box.bvh2, ray, hit, total);
    }
    CHECK(total.inner_nodes >= 1000);
    CHECK(total.triangle_tests >= total.leaf_nodes);
}
