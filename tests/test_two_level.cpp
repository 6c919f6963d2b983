// Two-level BVHs: every top level (flat, two-level, rebraid) and kernel agrees with brute force over the
// flattened world triangles, with instances rotated, scaled non-uniformly and overlapping; re-braiding is
// deterministic; transformed boxes are conservative.
#include "two_level_support.h"

#include <glm/gtc/matrix_transform.hpp>
#include <tbb/global_control.h>

#include <cstring>

using namespace canopy;
using namespace canopy::test;

TEST_CASE("every top level agrees with brute force over instanced, transformed objects", "[two-level]") {
    const Scene scene = instanced_scene();
    const FlatScene flat = flatten(scene);
    const std::vector<Ray> rays = random_rays(flat.triangles, 20000, 77);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const char* top : {"flat", "two-level", "rebraid"}) {
        for (const char* kernel : {"bvh2", "bvh4", "bvh8"}) {
            if (!kernel_compiled(kernel_width(kernel)) || !cpu_runs(kernel_width(kernel))) continue;
            auto accel = make_canopy_accelerator(scene, flat, {"binned", "", kernel, true, true, top});
            accel->prepare();
            accel->build();
            INFO(top << " " << kernel);
            // Only grazing hits at shared edges may differ, where world and object rounding disagree.
            CHECK(disagreements(*accel, rays, expected, 1e-5f * glm::length(flat.bounds.extent())) <= rays.size() / 1000);
        }
    }
    const auto embree = make_embree_two_level_accelerator(scene, flat, "medium", 0);  // the bench's reference row
    embree->prepare();
    embree->build();
    CHECK(disagreements(*embree, rays, expected, 1e-5f * glm::length(flat.bounds.extent())) <= rays.size() / 1000);
}

TEST_CASE("identity instances give exactly the flat BVH's hits", "[two-level]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=9");  // several objects, one identity instance
    const FlatScene flat = flatten(scene);
    const std::vector<Ray> rays = random_rays(flat.triangles, 10000, 78);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const char* top : {"two-level", "rebraid"}) {
        auto accel = make_canopy_accelerator(scene, flat, {"binned", "", "auto", true, true, top});
        accel->prepare();
        accel->build();
        std::vector<Hit> actual(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) actual[i] = accel->trace(rays[i]);
        CHECK(count_mismatches(rays, expected, actual, top) == 0);
    }
}

TEST_CASE("the re-braided top level is the same with 1 and 2 threads", "[two-level]") {
    const TwoLevelInput input = two_level_input(instanced_scene());
    auto build = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        return build_two_level<4>(input, TwoLevelSettings{});
    };
    const TwoLevelBvh<4> one = build(1), two = build(2);
    REQUIRE(one.pool.nodes.size() == two.pool.nodes.size());
    REQUIRE(one.entries.size() == two.entries.size());
    CHECK(one.brefs > input.instances.size());  // overlapping instances were opened
    CHECK(std::memcmp(one.pool.nodes.data(), two.pool.nodes.data(), one.pool.nodes.size() * sizeof(WideNode<4>)) == 0);
    CHECK(std::memcmp(one.entries.data(), two.entries.data(), one.entries.size() * sizeof(TopLevelRef)) == 0);
}

TEST_CASE("re-braiding lowers the SAH of the plain two-level top level", "[two-level]") {
    const TwoLevelInput input = two_level_input(instanced_scene());
    TwoLevelSettings plain;
    plain.top = TopLevel::TwoLevel;
    CHECK(sah_cost(build_two_level<4>(input, TwoLevelSettings{})) < sah_cost(build_two_level<4>(input, plain)));
}

TEST_CASE("transformed boxes contain every transformed point", "[two-level]") {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int i = 0; i < 500; ++i) {
        glm::mat4 m(1.0f);
        m = glm::translate(m, Vec3(u(rng), u(rng), u(rng)) * 1e4f);
        m = glm::rotate(m, 3.0f * u(rng), glm::normalize(Vec3(u(rng), u(rng), u(rng)) + Vec3(0, 0, 2)));
        m = glm::scale(m, Vec3(std::exp(5.0f * u(rng)), std::exp(5.0f * u(rng)), std::exp(5.0f * u(rng))));
        const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
        const BBox box{glm::min(a, b), glm::max(a, b)};
        const BBox world = transform_bounds(m, box);
        for (int k = 0; k < 20; ++k) {
            const glm::dvec3 p = glm::mix(glm::dvec3(box.lower), glm::dvec3(box.upper),
                                          glm::dvec3(0.5 + 0.5 * u(rng), 0.5 + 0.5 * u(rng), 0.5 + 0.5 * u(rng)));
            const glm::dvec4 q = glm::dmat4(m) * glm::dvec4(p, 1.0);
            for (int axis = 0; axis < 3; ++axis) {
                CHECK(q[axis] >= double(world.lower[axis]));
                CHECK(q[axis] <= double(world.upper[axis]));
            }
        }
    }
}
