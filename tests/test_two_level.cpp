// Two-level BVHs: every top level (flat, two-level, rebraid) and kernel agrees with brute force over the
// flattened world triangles, with instances rotated, scaled non-uniformly and overlapping; re-braiding is
// deterministic; transformed boxes are conservative.
#include "two_level_support.h"
#include "experiments/embree_accelerator.h"
#include "kernels/traverse_two_level.h"

#include <glm/gtc/matrix_transform.hpp>
#include <tbb/global_control.h>

#include <algorithm>
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

// Embree reports an instanced triangle's normal in object space; shading turns it to world space. With the normal
// left in object space, the rotated, non-uniformly scaled instances would scatter their paths elsewhere.
TEST_CASE("Embree's two-level rows shade instanced triangles as its flat row does", "[two-level][embree]") {
    const Scene scene = instanced_scene();
    const FlatScene flat = flatten(scene);
    const auto flat_embree = make_embree_accelerator(flat, "medium", 0);
    const auto two_level = make_embree_two_level_accelerator(scene, flat, "medium", 0);
    for (Accelerator* accel : {flat_embree.get(), two_level.get()}) {
        accel->prepare();
        accel->build();
    }
    const auto frame_of = [&](const Accelerator& accel, TracerKind tracer) {
        FrameSettings settings;
        settings.width = 96, settings.height = 72, settings.tracer = tracer, settings.stream_paths = 1000;
        const ShadingScene shading{flat, settings};
        Image image(settings.width, settings.height);
        const uint64_t rays = canopy::render(accel, shading, PinholeCamera(scene_camera(scene, flat), settings.width, settings.height), 0, image);
        return std::pair{rays, image.mean(1)};
    };
    const auto [flat_rays, flat_mean] = frame_of(*flat_embree, TracerKind::Single);
    for (const TracerKind tracer : {TracerKind::Single, TracerKind::Stream}) {
        const auto [rays, mean] = frame_of(*two_level, tracer);
        INFO((tracer == TracerKind::Single ? "single" : "stream"));
        // Object-space rounding moves a few grazing hits: statistics, not bits.
        CHECK(double(rays) == Approx(double(flat_rays)).epsilon(0.002));
        CHECK(mean == Approx(flat_mean).epsilon(0.005));
    }
}

TEST_CASE("re-braiding agrees with brute force at every opening threshold, and opens more BRefs at a lower one", "[two-level]") {
    const Scene scene = instanced_scene();
    const FlatScene flat = flatten(scene);
    const std::vector<Ray> rays = random_rays(flat.triangles, 20000, 78);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    std::vector<uint64_t> brefs;
    for (const float threshold : {1.0f, 0.1f, 0.0f}) {
        CanopyOptions options{"binned", "", "auto", true, true, "rebraid"};
        options.rebraid_threshold = threshold;
        auto accel = make_canopy_accelerator(scene, flat, options);
        accel->prepare();
        accel->build();
        INFO("threshold " << threshold);
        CHECK(disagreements(*accel, rays, expected, 1e-5f * glm::length(flat.bounds.extent())) <= rays.size() / 1000);
        brefs.push_back(*accel->report(false).brefs);
    }
    CHECK(brefs[0] < brefs[2]);
    CanopyOptions out_of_range{"binned", "", "auto", true, true, "rebraid"};
    out_of_range.rebraid_threshold = 1.5f;
    CHECK_THROWS_WITH(make_canopy_accelerator(scene, flat, out_of_range), Catch::Contains("from 0 to 1"));
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

namespace {

// A room of identity objects, and "shards": one object of two far-apart hollow boxes, each of four side walls
// (two triangles each) spanning a third of the room, placed once by the identity and once rotated, scaled
// non-uniformly and moved. A box's walls make one leaf whose box holds the whole box, as crytek-sponza's outer
// walls do: the leaves re-braiding opens into triangles, the transformed copy's in world space.
Scene shard_scene() {
    Scene scene = load_scene("gen:box?tris=1500&seed=4");
    const BBox room = flatten(scene).bounds;
    Mesh shards;
    shards.name = "shards";
    for (const float corner : {0.1f, 0.6f}) {
        const Vec3 lower = room.lower + corner * room.extent(), size = 0.3f * room.extent();
        for (int wall = 0; wall < 4; ++wall) {
            const int axis = wall / 2 == 0 ? 0 : 2, across = axis == 0 ? 2 : 0;  // walls normal to x, then to z
            Vec3 base = lower;
            base[axis] += wall % 2 ? size[axis] : 0.0f;
            Vec3 along(0.0f), up(0.0f);
            along[across] = size[across], up[1] = size[1];
            const uint32_t first = uint32_t(shards.positions.size());
            shards.positions.insert(shards.positions.end(), {base, base + along, base + along + up, base + up});
            shards.triangles.push_back({first, first + 1, first + 2});
            shards.triangles.push_back({first, first + 2, first + 3});
        }
    }
    shards.objects = {{"shards", 0, uint32_t(shards.triangles.size())}};
    scene.meshes.push_back(shards);
    glm::mat4 moved = glm::translate(glm::mat4(1.0f), room.center());
    moved = glm::rotate(moved, 0.9f, glm::normalize(Vec3(1, 3, 2)));
    moved = glm::scale(moved, Vec3(0.8f, 0.5f, 0.7f));
    moved = glm::translate(moved, -room.center());
    scene.instances.push_back({1, glm::mat4(1.0f)});
    scene.instances.push_back({1, moved});
    return scene;
}

// The top level's own leaves (after the object trees' in the pool): the scene-wide triangle ids they hold.
template <int N>
std::vector<uint32_t> top_level_triangles(const TwoLevelBvh<N>& bvh) {
    std::vector<uint32_t> prims;
    for (size_t i = bvh.object_leaves; i < bvh.pool.leaves.size(); ++i) {
        if constexpr (N == 2) {
            prims.push_back(bvh.pool.leaves[i].prim);
        } else {
            for (uint32_t prim : bvh.pool.leaves[i].prim)
                if (prim != TriangleBlock<block_lanes(N)>::kNone) prims.push_back(prim);
        }
    }
    return prims;
}

template <int N>
void check_opened_leaves(const Scene& scene) {
    const FlatScene flat = flatten(scene);
    const TwoLevelInput input = two_level_input(scene);
    TwoLevelSettings settings;
    settings.blas.leaf_block = 4;  // as the renderer builds for the SIMD kernels: leaves of up to 8
    settings.brefs_per_placement = 16;
    const TwoLevelBvh<N> bvh = build_two_level<N>(input, settings);
    const std::vector<uint32_t> prims = top_level_triangles(bvh);
    const uint32_t shards = uint32_t(flat.triangles.size() - 32), moved = shards + 16;  // the last two placements
    INFO("bvh" << N);
    CHECK(std::count_if(prims.begin(), prims.end(), [&](uint32_t p) { return p >= shards && p < moved; }) > 0);
    CHECK(std::count_if(prims.begin(), prims.end(), [&](uint32_t p) { return p >= moved; }) > 0);
    // Opened triangles of the transformed placement are placed as flatten() places them; rays entering its
    // unopened nodes still traverse in object space, hence the tolerance of the other two-level tests.
    const std::vector<Ray> rays = random_rays(flat.triangles, 20000, 79);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    std::vector<Hit> actual(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) closest_hit(bvh, rays[i], actual[i]);
    CHECK(disagreements_of(rays, expected, actual, 1e-5f * glm::length(flat.bounds.extent())) <= rays.size() / 1000);
}

}  // namespace

TEST_CASE("re-braiding opens wide leaves into top-level leaves of world-space triangles", "[two-level]") {
    const Scene scene = shard_scene();
    check_opened_leaves<2>(scene);
    if (kernel_compiled(4) && cpu_runs(4)) check_opened_leaves<4>(scene);
    if (kernel_compiled(8) && cpu_runs(8)) check_opened_leaves<8>(scene);
}

TEST_CASE("instance entries may outnumber the object leaves", "[two-level]") {
    Scene scene;
    Mesh one;
    one.name = "one";
    one.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
    one.triangles = {{0, 1, 2}};
    one.objects = {{"one", 0, 1}};
    scene.meshes.push_back(one);
    for (int i = 0; i < 40; ++i)
        scene.instances.push_back({0, glm::rotate(glm::translate(glm::mat4(1.0f), Vec3(0.3f * float(i), 0, 0)),
                                                  0.2f * float(i), Vec3(0, 1, 0))});
    const FlatScene flat = flatten(scene);
    // Rays from one of these crossing triangles to another re-hit their start in object space or not, by rounding.
    const std::vector<Ray> rays = off_surface(random_rays(flat.triangles, 5000, 80));
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const TopLevel top : {TopLevel::TwoLevel, TopLevel::Rebraid}) {
        TwoLevelSettings settings;
        settings.top = top;
        const TwoLevelBvh<4> bvh = build_two_level<4>(two_level_input(scene), settings);
        REQUIRE(bvh.entries.size() > bvh.object_leaves);
        CHECK(bvh.pool.leaves.size() >= bvh.entries.size());  // an entry's index stays inside the leaves
        std::vector<Hit> actual(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) closest_hit(bvh, rays[i], actual[i]);
        CHECK(disagreements_of(rays, expected, actual, 1e-5f * glm::length(flat.bounds.extent())) <= rays.size() / 1000);
    }
}

TEST_CASE("the top level's bins must fit its binning", "[two-level]") {
    const TwoLevelInput input = two_level_input(instanced_scene());
    for (uint32_t bins : {0u, 1u, 65u}) {
        TwoLevelSettings settings;
        settings.bins = bins;
        CHECK_THROWS_AS(build_two_level<4>(input, settings), std::invalid_argument);
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
    REQUIRE(one.pool.leaves.size() == two.pool.leaves.size());
    CHECK(one.pool.leaves.size() > one.object_leaves);  // leaves were opened into the top level's own
    CHECK(std::memcmp(one.pool.leaves.data(), two.pool.leaves.data(), one.pool.leaves.size() * sizeof(one.pool.leaves[0])) == 0);
}

TEST_CASE("both top levels over hundreds of placements are the same with 1 and 2 threads", "[two-level]") {
    // Enough BRefs that the top level's subtrees build as parallel tasks, the plain top level's included.
    Scene scene = load_scene("gen:surface?tris=800&seed=9");
    for (int i = 0; i < 300; ++i) {
        const glm::mat4 moved = glm::translate(glm::mat4(1.0f), Vec3(0.7f * float(i % 17), 0.3f * float(i % 5), 0.9f * float(i / 17)));
        scene.instances.push_back({0, glm::rotate(moved, 0.37f * float(i), glm::normalize(Vec3(1, 2 + i % 3, 3)))});
    }
    const TwoLevelInput input = two_level_input(scene);
    for (const TopLevel top : {TopLevel::TwoLevel, TopLevel::Rebraid}) {
        TwoLevelSettings settings;
        settings.top = top;
        auto build = [&](int threads) {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
            return build_two_level<4>(input, settings);
        };
        const TwoLevelBvh<4> one = build(1), two = build(2);
        INFO((top == TopLevel::Rebraid ? "rebraid" : "two-level"));
        REQUIRE(one.pool.nodes.size() == two.pool.nodes.size());
        REQUIRE(one.entries.size() == two.entries.size());
        REQUIRE(one.pool.leaves.size() == two.pool.leaves.size());
        CHECK(one.pool.nodes.size() - one.object_nodes > 64 / 4);  // a top level of many nodes, not one leaf
        CHECK(std::memcmp(one.pool.nodes.data(), two.pool.nodes.data(), one.pool.nodes.size() * sizeof(WideNode<4>)) == 0);
        CHECK(std::memcmp(one.entries.data(), two.entries.data(), one.entries.size() * sizeof(TopLevelRef)) == 0);
        CHECK(std::memcmp(one.pool.leaves.data(), two.pool.leaves.data(), one.pool.leaves.size() * sizeof(one.pool.leaves[0])) == 0);
    }
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

// Shading reads the hit triangle's corners from the leaf the kernel has just read, as in a flat tree: a transformed
// instance's taken to world space, an identity placement's as they are.
TEST_CASE("two-level kernels hand over the hit triangle's world corners", "[two-level]") {
    const Scene scene = instanced_scene();
    const FlatScene flat = flatten(scene);
    const std::vector<Ray> rays = random_rays(flat.triangles, 20000, 91);
    const float tolerance = 1e-5f * glm::length(flat.bounds.extent());
    for (const char* toplevel : {"two-level", "rebraid"}) {
        for (const char* kernel : {"bvh2", "bvh8"}) {
            INFO(toplevel << " " << kernel);
            CanopyOptions options{"binned", "", kernel, true, true, toplevel};
            auto accel = make_canopy_accelerator(scene, flat, options);
            accel->prepare();
            accel->build();
            size_t hits = 0, far = 0;
            std::visit([&]<class Kernel>(const Kernel& k) {
                if constexpr (requires(Hit& hit, Triangle& corners) { k.closest(rays[0], hit, corners); }) {
                    for (const Ray& ray : rays) {
                        Hit hit;
                        Triangle corners;
                        if (!k.closest(ray, hit, corners)) continue;
                        ++hits;
                        const Triangle& t = flat.triangles[hit.prim];
                        far += glm::distance(corners.v0, t.v0) > tolerance || glm::distance(corners.v1, t.v1) > tolerance ||
                               glm::distance(corners.v2, t.v2) > tolerance;
                    }
                } else {
                    FAIL("the two-level kernel hands over no corners");
                }
            }, accel->bound_kernel());
            CHECK(hits > rays.size() / 4);
            CHECK(far == 0);
        }
    }
}
