// Memory bounds: the estimate grows with what a build holds, the bound is the least of the machine's and the
// caller's, and load_scene asks before it generates a scene or before instancing multiplies a file's triangles.
#include "scenes_test_support.h"
#include "accel/builder.h"
#include "accel/memory_budget.h"

using namespace canopy;
using namespace canopy::test;

namespace {

MemoryEstimate estimate_for(const SceneSize& size, BuildPlan plan) {
    return estimate_memory(size, {&plan, 1});
}
// A plan with the builder's reference cap and auto's candidates from the registry, as the commands make it.
MemoryEstimate estimate_for(const SceneSize& size, const std::string& builder, int width, bool two_level) {
    return estimate_for(size, make_build_plan(builder, width, two_level));
}

}  // namespace

TEST_CASE("the memory estimate follows the leaf policy, the layout's bytes, reference caps and rows", "[scenes][memory]") {
    const SceneSize small{3000, 1000, 1000, 1}, large{3'000'000, 1'000'000, 1'000'000, 1};
    const double n = 1'000'000;
    CHECK(estimate_for(large, {}).total() > 900 * estimate_for(small, {}).total());
    // Block leaves fill to 6 of their 8 triangles: a binary node pair and a 320-byte block per 6 triangles, a wide
    // node per 4 leaves; the PrimRefs and their scratch are freed before the layout, which is as large, is written.
    const MemoryEstimate binned = estimate_for(large, "binned", 8, false);
    CHECK(double(binned.binary) / n == Approx(2.0 * 32.0 / 6.0 + 4.0).epsilon(1e-3));
    CHECK(double(binned.layout) / n == Approx(320.0 / 6.0 + 256.0 / 24.0).epsilon(1e-3));
    CHECK(binned.references < uint64_t(n));
    CHECK(binned.flat == uint64_t(n) * (sizeof(Triangle) + sizeof(uint32_t)));
    CHECK(binned.process == 0);
    CHECK(binned.frames == 0);
    // The scalar kernel's binary leaves hold two triangles, each a 40-byte LeafTriangle.
    const MemoryEstimate bvh2 = estimate_for(large, "binned", 2, false);
    CHECK(double(bvh2.binary) / n == Approx(32.0 + 4.0).epsilon(1e-3));
    CHECK(double(bvh2.layout) / n == Approx(40.0 + 32.0).epsilon(1e-3));
    // sbvh may double its references: its trees double.
    const MemoryEstimate sbvh = estimate_for(large, "sbvh", 8, false);
    CHECK(double(sbvh.layout) == Approx(2.0 * double(binned.layout)).epsilon(1e-5));
    CHECK(double(sbvh.binary) == Approx(2.0 * double(binned.binary)).epsilon(1e-5));
    CHECK(sbvh.scene == binned.scene);
    // Embree's row: its copy of the triangles and indices, its PrimRefs while it builds, its tree.
    const MemoryEstimate embree = estimate_for(large, "embree", 8, false);
    CHECK(embree.flat == binned.flat + uint64_t(n) * (sizeof(Triangle) + 3 * sizeof(uint32_t)));
    CHECK(embree.references == uint64_t(n) * sizeof(PrimRef));
    CHECK(embree.binary == 0);
    CHECK(embree.layout > uint64_t(n) * 64);
    // A two-level build copies object triangles and keeps per-placement data.
    const SceneSize instanced{3000, 1000, 1'000'000, 1000};
    CHECK(estimate_for(instanced, "binned", 8, true).layout > estimate_for(small, "binned", 8, true).layout);
    // "auto" plans for the largest build it may choose; the bench for all its rows' trees, and for one build's
    // scratch at a time, as its rows build one after another.
    CHECK(estimate_for(large, "auto", 8, false).total() >= estimate_for(large, "esc", 8, false).total());
    const MemoryEstimate rows = estimate_memory(large, std::vector<BuildPlan>(3, BuildPlan{}));
    CHECK(rows.binary == 3 * binned.binary);
    CHECK(rows.layout == 3 * binned.layout);
    CHECK(rows.references == binned.references);
    CHECK(estimate_memory(large, std::vector<BuildPlan>{BuildPlan{}, {"embree", 8, false}}).references == embree.references);
}

TEST_CASE("the memory bound is the least of what the machine has and the limit given", "[scenes][memory]") {
    const MemoryAvailable machine = available_memory(std::nullopt);
    CHECK(machine.bytes > (64u << 20));
    CHECK(!machine.source.empty());
    const MemoryAvailable limited = available_memory(1u << 20);
    CHECK(limited.bytes == (1u << 20));
    CHECK(limited.source == "--memory-limit");
    CHECK(available_memory(UINT64_MAX).source == machine.source);  // a limit never raises the bound
}

TEST_CASE("a build that does not fit is refused with the estimate and the memory available", "[scenes][memory]") {
    MemoryEstimate estimate = estimate_for({3'000'000, 1'000'000, 1'000'000, 1}, {});
    estimate.references = 1u << 20;  // every term named
    CHECK_NOTHROW(require_memory("scene", estimate, {estimate.total(), "test"}));
    try {
        require_memory("big.obj", estimate, {estimate.total() - 1, "--memory-limit"});
        FAIL("no MemoryError");
    } catch (const MemoryError& e) {
        const std::string message = e.what();
        CHECK_THAT(message, Catch::Contains("big.obj: not enough memory"));
        CHECK_THAT(message, Catch::Contains(format_bytes(estimate.total())));
        CHECK_THAT(message, Catch::Contains("references and build scratch"));
        CHECK_THAT(message, Catch::Contains("binary BVH"));
        CHECK_THAT(message, Catch::Contains(format_bytes(estimate.total() - 1) + " is available (--memory-limit)"));
    }
    // A kd-tree has no binary BVH: its estimate does not name one.
    const MemoryEstimate kd = estimate_for({3'000'000, 1'000'000, 1'000'000, 1}, "kdtree", 2, false);
    CHECK(kd.binary == 0);
    CHECK_THAT(kd.describe(), !Catch::Contains("binary BVH"));
    // A rounding remainder is not a term: PrimRefs that the layout's bytes cover leave a byte or so over.
    MemoryEstimate remainder = estimate;
    remainder.references = 1;
    CHECK_THAT(remainder.describe(), !Catch::Contains("references and build scratch"));
    CHECK(format_bytes(512) == "512 bytes");
    CHECK(format_bytes(3u << 20) == "3.0 MiB");
    CHECK(format_bytes(uint64_t(5) << 40) == "5.0 TiB");
}

TEST_CASE("a generator spec is sized before anything is generated", "[scenes][memory]") {
    SceneSize seen;
    const auto refuse = [&](const SceneSize& size) {
        seen = size;
        throw MemoryError("refused");
    };
    CHECK_THROWS_AS(load_scene("gen:triangles?tris=400000000&seed=1", refuse), MemoryError);
    CHECK(seen.triangles >= 400'000'000);
    CHECK(seen.vertices >= 3 * seen.triangles);
    // Each generator's size bounds what it makes: the check sees no less than the scene holds.
    for (const char* spec : {"gen:box?tris=5000&seed=2", "gen:cylinders?tris=5001", "gen:mirror?tris=5001",
                             "gen:surface?tris=31", "gen:triangles?tris=7", "gen:box?tris=1", "gen:mirror?tris=1"}) {
        INFO(spec);
        const Scene scene = load_scene(spec, [&](const SceneSize& size) { seen = size; });
        const SceneSize made = scene_size(scene);
        CHECK(made.triangles <= seen.triangles);
        CHECK(made.vertices <= seen.vertices);
    }
    CHECK_THROWS_AS(load_scene("gen:box?tris=abc", [](const SceneSize&) {}), InputError);
}

TEST_CASE("a file is sized once loaded, before instancing multiplies it", "[scenes][memory]") {
    TempDir dir;
    dir.write("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    std::string instances;
    for (int i = 0; i < 300; ++i) instances += std::string(i ? "," : "") + R"({"mesh": "tri"})";
    const std::string scene = dir.write("many.json", R"({"meshes": [{"name": "tri", "file": "tri.obj"}], "instances": [)" + instances + "]}");
    SceneSize seen;
    const Scene loaded = load_scene(scene, [&](const SceneSize& size) { seen = size; });
    CHECK(seen.triangles == 1);
    CHECK(seen.vertices == 3);
    CHECK(seen.instanced_triangles == 300);
    CHECK(seen.instances == 300);
    CHECK_THROWS_AS(load_scene(scene, [](const SceneSize& size) {
        require_memory("many.json", estimate_memory(size, {}), {1024, "test"});
    }), MemoryError);
}
