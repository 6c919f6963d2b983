// The benchmark protocol's camera, path tracer, ray offset, EXR output and bench report.
#include "oracle.h"
#include "renderer/accelerator.h"
#include "renderer/commands/bench.h"
#include "renderer/auto_builder.h"
#include "accel/builders/early_split_clipping.h"
#include "renderer/commands/heatmap.h"

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <filesystem>
#include <map>
#include <set>
#include <fstream>

using namespace canopy;
using namespace canopy::test;

namespace {

struct Rendered {
    double mean;
    uint64_t rays;
};

Rendered render_once(const Accelerator& accel, const FlatScene& flat, const Camera& cam, int w, int h, int bounces = 8) {
    FrameSettings settings;
    settings.width = w, settings.height = h, settings.max_bounces = bounces;
    const ShadingScene shading{flat, settings};
    Image image(w, h);
    const uint64_t rays = accel.render(shading, PinholeCamera(cam, w, h), 0, image);
    return {image.mean(1), rays};
}

std::unique_ptr<Accelerator> built(std::unique_ptr<Accelerator> accel) {
    accel->prepare();
    accel->build();
    return accel;
}

}  // namespace

TEST_CASE("camera rays follow BENCHMARK.md", "[render]") {
    const Camera cam{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 90.0f};
    const PinholeCamera camera(cam, 200, 100);
    const Ray centre = camera.generate(100, 50, 0.0f, 0.0f);
    CHECK(centre.dir.x == Approx(0).margin(1e-6));
    CHECK(centre.dir.z == Approx(-1));
    // Top-left corner: sx = -tan(45) * 2, sy = +tan(45): row 0 is the top row.
    const Ray corner = camera.generate(0, 0, 0.0f, 0.0f);
    const Vec3 expected = glm::normalize(Vec3(-2, 1, -1));
    CHECK(corner.dir.x == Approx(expected.x));
    CHECK(corner.dir.y == Approx(expected.y));
    CHECK(corner.dir.z == Approx(expected.z));
}

TEST_CASE("the sampler's turn is libm's cos and sin within 2e-7, and its directions are cosine-weighted", "[render]") {
    double worst = 0.0;
    for (uint32_t i = 0; i < (1u << 20); ++i) {  // every 2^-20 of a turn, the quarter turns' edges included
        const float u = float(i) * 0x1p-20f;
        const auto [c, s] = turn_cos_sin(u);
        const double phi = 6.283185307179586 * double(u);
        worst = std::max({worst, std::abs(double(c) - std::cos(phi)), std::abs(double(s) - std::sin(phi))});
    }
    CHECK(worst < 2e-7);
    // E[cos theta] of a cosine-weighted hemisphere is 2/3, and the tangent components average 0.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const Vec3 n = glm::normalize(Vec3(0.3f, -0.8f, 0.5f));
    Vec3 sum(0.0f);
    for (int i = 0; i < 200000; ++i) {
        const Vec3 d = cosine_direction(n, u(rng), u(rng));
        REQUIRE(std::abs(glm::length(d) - 1.0f) < 1e-6f);
        REQUIRE(glm::dot(d, n) >= 0.0f);
        sum += d;
    }
    const Vec3 mean = sum / 200000.0f;
    CHECK(std::abs(glm::dot(mean, n) - 2.0f / 3.0f) < 0.005f);
    CHECK(glm::length(mean - glm::dot(mean, n) * n) < 0.005f);
}

TEST_CASE("offset origins leave the surface on the normal's side at every magnitude", "[render]") {
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (float magnitude : {0.0f, 1e-3f, 1.0f, 1e3f, 1e5f, 1e7f}) {
        // A large triangle in the plane through (m, m, m) with a tilted normal.
        const Vec3 c(magnitude), n = glm::normalize(Vec3(0.3f, 1.0f, -0.2f));
        const Vec3 t = glm::normalize(glm::cross(n, Vec3(1, 0, 0))), s = glm::cross(n, t);
        const float size = std::max(1.0f, magnitude);
        const std::vector<Triangle> tri{{c - size * (t + s), c + size * (2.0f * t - s), c + size * (2.0f * s - t)}};
        const BuiltScene scene = build_with("binned", tri);
        size_t self_hits = 0;
        for (int i = 0; i < 2000; ++i) {
            float a = u(rng), b = u(rng);
            if (a + b > 1) a = 1 - a, b = 1 - b;
            const Triangle& tr = tri[0];
            const Vec3 p = tr.v0 + a * (tr.v1 - tr.v0) + b * (tr.v2 - tr.v0);
            const Vec3 side = (i % 2) ? n : -n;
            const Ray ray{offset_ray_origin(p, side), cosine_direction(side, u(rng), u(rng))};
            Hit hit;
            self_hits += closest_hit(scene.bvh2, ray, hit);
        }
        INFO("magnitude " << magnitude);
        CHECK(self_hits == 0);
    }
}

// Rays leaving conference's floor: two coplanar triangles 2600 units wide, so their vertices lie far from the
// hit points, in one leaf with a small triangle above them (so the leaf's box is not flat). The hit point's
// magnitude alone gives too small an offset (3e-5 at y = -1.57): a ray leaving the floor upwards "hits" it at
// t ~ 5e-5, is turned to the other side and escapes below the floor. The first four rays are such rays,
// recorded in conference; the others are random.
size_t self_hits_on_huge_floor(bool with_triangle_error) {
    const float floor_y = -0x1.927914p+0f;
    const std::vector<Triangle> scene{
        {Vec3(-0x1.d971aap+9f, floor_y, -0x1.fc0cccp+9f), Vec3(-0x1.d971aap+9f, floor_y, 0x1.4e3e98p+9f),
         Vec3(0x1.9d5p+10f, floor_y, -0x1.fc0cccp+9f)},
        {Vec3(-0x1.d971aap+9f, floor_y, 0x1.4e3e98p+9f), Vec3(0x1.9d5p+10f, floor_y, 0x1.4e3e98p+9f),
         Vec3(0x1.9d5p+10f, floor_y, -0x1.fc0cccp+9f)},
        {Vec3(0, 1, 0), Vec3(1, 1, 0), Vec3(0, 1, 1)}};
    const BuiltScene built = build_with("binned", scene);
    REQUIRE(built.binary.nodes.size() == 1);  // one leaf, as in conference
    std::vector<std::pair<Vec3, Vec3>> departures{  // point on the floor, direction
        {{0x1.11ec5cp+9f, floor_y, -0x1.610a78p+7f}, {0x1.7f55d2p-1f, 0x1.9ce6b8p-2f, -0x1.0d6656p-1f}},
        {{0x1.8b938ap+9f, floor_y, 0x1.f5872p+6f}, {0x1.842064p-1f, 0x1.3ee11p-1f, 0x1.8c576ep-3f}},
        {{0x1.10b4d8p+9f, floor_y, 0x1.59b97cp+8f}, {-0x1.69c59cp-1f, 0x1.4a5732p-1f, -0x1.29977ap-2f}},
        {{-0x1.0d366p+7f, floor_y, 0x1.2a03cp+5f}, {0x1.e1507p-2f, 0x1.0ef45p-1f, -0x1.69ade6p-1f}}};
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int i = 0; i < 50000; ++i) {
        const Triangle& t = scene[i % 2];
        float a = u(rng), b = u(rng);
        if (a + b > 1) a = 1 - a, b = 1 - b;
        departures.push_back({t.v0 + a * (t.v1 - t.v0) + b * (t.v2 - t.v0), cosine_direction(Vec3(0, 1, 0), u(rng), u(rng))});
    }
    const float error = with_triangle_error ? triangle_point_error(scene[0]) : 0.0f;
    size_t self_hits = 0;
    for (const KernelUnderTest& kernel : kernels_of(built)) {
        for (const auto& [p, dir] : departures) {
            const Hit hit = kernel.closest(Ray{offset_ray_origin(p, Vec3(0, 1, 0), error), dir});
            self_hits += hit.found() && hit.prim < 2;
        }
    }
    return self_hits;
}

TEST_CASE("rays leaving a huge floor never re-hit it", "[render]") {
    CHECK(self_hits_on_huge_floor(true) == 0);
    CHECK(self_hits_on_huge_floor(false) > 0);  // the failure the triangle term exists for
}

TEST_CASE("an empty sky gives one ray per path and radiance 1", "[render]") {
    FlatScene flat;
    flat.triangles = {{Vec3(0, 0, 10), Vec3(1, 0, 10), Vec3(0, 1, 10)}};  // behind the camera
    const Camera cam{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 60.0f};
    const auto accel = built(make_canopy_accelerator(flat, {}));
    const Rendered r = render_once(*accel, flat, cam, 32, 24);
    CHECK(r.rays == 32u * 24u);
    CHECK(r.mean == Approx(1.0));
}

TEST_CASE("a closed room gives max_bounces + 1 rays per path and no light", "[render]") {
    FlatScene flat;
    // The inside of a cube made of 12 triangles.
    const Vec3 p[8] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}};
    const int faces[6][4] = {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {3, 2, 6, 7}, {0, 3, 7, 4}, {1, 2, 6, 5}};
    for (const auto& f : faces) {
        flat.triangles.push_back({p[f[0]], p[f[1]], p[f[2]]});
        flat.triangles.push_back({p[f[0]], p[f[2]], p[f[3]]});
    }
    const Camera cam{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 60.0f};
    const auto accel = built(make_canopy_accelerator(flat, {}));
    const Rendered r = render_once(*accel, flat, cam, 16, 16, 8);
    CHECK(r.rays == 16u * 16u * 9u);
    CHECK(r.mean == 0.0);
}

TEST_CASE("canopy and Embree render the same picture with the same ray count", "[render][embree]") {
    const Scene scene = load_scene("");
    const FlatScene flat = flatten(scene);
    const Camera cam = scene_camera(scene, flat);
    const auto ours = built(make_canopy_accelerator(flat, {}));
    const auto embree = built(make_embree_accelerator(flat, "medium", 0));
    const Rendered a = render_once(*ours, flat, cam, 128, 96);
    const Rendered b = render_once(*embree, flat, cam, 128, 96);
    CHECK(a.mean == Approx(b.mean).epsilon(0.02));
    CHECK(double(a.rays) == Approx(double(b.rays)).epsilon(0.01));
}

TEST_CASE("Embree and canopy hit what brute force hits", "[embree]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=4000&seed=9"));
    // Rays that start on a surface are left out: there Embree's and canopy's intersectors differ by design
    // (self-hits at t ~ 1e-9); the path tracer offsets its origins instead.
    const std::vector<Ray> rays = off_surface(random_rays(flat.triangles, 20000, 51));
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    for (const auto& accel : {built(make_canopy_accelerator(flat, {})), built(make_embree_accelerator(flat, "medium", 0)),
                              built(make_embree_accelerator(flat, "high", 0))}) {
        std::vector<Hit> actual(rays.size());
        for (size_t i = 0; i < rays.size(); ++i) actual[i] = accel->trace(rays[i]);
        const std::string what = accel->library() + " " + accel->quality();
        // Embree's default intersector is not watertight: allow it a few edge cases, canopy none.
        const size_t allowed = accel->library() == "embree" ? rays.size() / 1000 : 0;
        CHECK(count_mismatches(rays, expected, actual, what, accel->library() == "canopy") <= allowed);
    }
}

TEST_CASE("EXR output holds the rendered values", "[render]") {
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_output.exr").string();
    std::vector<float> rgb(8 * 4 * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = float(i) * 0.25f;
    write_exr(path, 8, 4, rgb);
    auto in = OIIO::ImageInput::open(path);
    REQUIRE(in);
    CHECK(in->spec().width == 8);
    CHECK(in->spec().nchannels == 3);
    std::vector<float> back(rgb.size());
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, back.data()));
    CHECK(back == rgb);
    CHECK_THROWS_WITH(write_exr("/nonexistent-dir/x.exr", 8, 4, rgb), Catch::Contains("/nonexistent-dir/x.exr"));
    CHECK(read_exr(path, 8, 4) == rgb);  // the tradeoff command's cached reference
    CHECK_THROWS_WITH(read_exr(path, 4, 8), Catch::Contains("expected 4x8"));
}

TEST_CASE("RMSE against a reference is the root of the mean squared difference", "[render]") {
    std::vector<float> a(4 * 2 * 3, 0.5f), b = a;
    b[0] = 1.5f;  // one channel of one pixel off by 1: mean square 1/24
    CHECK(rms_error(a, b, 4, 2) == Approx(std::sqrt(1.0 / 24.0)));
    CHECK(rms_error(a, a, 4, 2) == 0.0);
}

TEST_CASE("bench writes the documented JSON", "[bench][embree]") {
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_bench.json").string();
    BenchOptions o;
    o.scene = "gen:box?tris=2000&seed=2";
    o.embree_qualities = {"medium"};
    o.builds = 2, o.frames = 2, o.width = 48, o.height = 32;
    o.json_path = path;
    run_bench(o);
    std::ifstream in(path);
    const nlohmann::json j = nlohmann::json::parse(in);
    for (const char* key : {"scene", "tris", "threads", "width", "height", "bounces", "results"}) CHECK(j.contains(key));
    REQUIRE(j["results"].size() == 2);
    for (const auto& r : j["results"]) {
        for (const char* key : {"accel", "builder", "kernel", "quality", "build_ms_min", "build_ms_median", "mprims_per_s",
                                "frame_ms_mean", "frame_ms_median", "rays_per_frame", "mrays_per_s", "sah", "epo", "nodes",
                                "leaves", "refs_per_tri", "bytes", "image_mean"})
            CHECK(r.contains(key));
        CHECK(r["rays_per_frame"].get<double>() >= 48 * 32);
    }
    CHECK(j["results"][0]["accel"] == "canopy");
    CHECK(j["results"][0]["sah"].is_number());
    CHECK(j["results"][1]["accel"] == "embree");
    CHECK(j["results"][1]["builder"].is_null());
    CHECK(j["results"][1]["sah"].is_null());
    CHECK(j["results"][0]["image_mean"].get<double>() ==
          Approx(j["results"][1]["image_mean"].get<double>()).epsilon(0.02));
    CHECK(j["results"][0]["lines_per_ray"].get<double>() > 0.0);
    CHECK(j["results"][1]["lines_per_ray"].is_null());
}

TEST_CASE("bench plans the memory of the rows it makes, no more", "[bench]") {
    BenchOptions o;
    o.builders = {"binned", "esc", "esc:sa_max=8x", "auto"};
    o.kernels = {"bvh8"};
    o.toplevels = {"flat", "rebraid"};
    o.rebraid_thresholds = {0.1f, 0.2f};
    o.frames_planned = {1, 16, 256};
    o.embree_qualities = {};
    // Flat: binned and each esc 1 row, auto 3 (a frame count each); rebraid: binned and each esc 2 (a threshold
    // each), auto none (it chooses its own top level).
    std::map<std::pair<std::string, bool>, int> rows;
    for (const BuildPlan& plan : build_plans(o)) ++rows[{plan.builder, plan.two_level}];
    const std::map<std::pair<std::string, bool>, int> expected{
        {{"binned", false}, 1}, {{"esc", false}, 1}, {{"esc:sa_max=8x", false}, 1}, {{"auto", false}, 3},
        {{"binned", true}, 2}, {{"esc", true}, 2}, {{"esc:sa_max=8x", true}, 2}};
    CHECK(rows == expected);
}

TEST_CASE("bench runs once per thread count, each row saying which", "[bench][embree]") {
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_bench_threads.json").string();
    BenchOptions o;
    o.scene = "gen:box?tris=2000&seed=2";
    o.embree_qualities = {"medium"};
    o.builds = 1, o.frames = 1, o.width = 24, o.height = 16, o.epo = false;
    o.threads = {1, 2};
    o.json_path = path;
    run_bench(o);
    std::ifstream in(path);
    const nlohmann::json j = nlohmann::json::parse(in);
    CHECK(j["threads"] == nlohmann::json({1, 2}));
    REQUIRE(j["results"].size() == 4);
    const int expected[] = {1, 1, 2, 2};
    for (size_t i = 0; i < 4; ++i) CHECK(j["results"][i]["threads"] == expected[i]);
    // The same tree and rays under either count: what a ray visits does not depend on the threads.
    CHECK(j["results"][0]["lines_per_ray"] == j["results"][2]["lines_per_ray"]);
}

// Frames through the counting kernel trace the rays render() traces, and read at least a node's lines per inner
// node and a leaf entry's per leaf, at most an entry's per triangle tested.
TEST_CASE("a counted frame's cache lines follow the layout's node and leaf sizes", "[render][counts]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=4");
    const FlatScene flat = flatten(scene);
    const PinholeCamera camera(*scene.camera, 24, 16);
    FrameSettings settings;
    settings.width = 24, settings.height = 16;
    const ShadingScene shading{flat, settings, nullptr};
    const std::pair<int, double> node_lines[] = {{2, 1.0}, {4, 2.0}, {8, 4.0}};
    for (const auto& [width, lines_per_node] : node_lines) {
        CAPTURE(width);
        auto accel = make_canopy_accelerator(flat, {"binned", "", "bvh" + std::to_string(width)});
        accel->prepare();
        accel->build();
        Image image(24, 16);
        const uint64_t rays = accel->render(shading, camera, 1, image);
        const auto [counts, counted_rays] = accel->count_frame(shading, camera, 1);
        CHECK(counted_rays == rays);
        const double entry_lines = width == 2 ? 48.0 / 64.0 : double(sizeof(TriangleBlock<block_lanes(4)>)) / 64.0;
        CHECK(double(counts.cache_lines) >= lines_per_node * double(counts.inner_nodes) +
                                              (width == 2 ? 1.0 : entry_lines) * double(counts.leaf_nodes));
        CHECK(double(counts.cache_lines) <= lines_per_node * double(counts.inner_nodes) +
                                              std::ceil(entry_lines + 1.0) * double(counts.triangle_tests));
    }
}

TEST_CASE("a span of bytes touches the 64-byte lines it overlaps", "[counts]") {
    TraversalCounts counts;
    alignas(64) static const char memory[512] = {};
    counts.touch(memory, 256);  // a BVH8 node on its own lines
    CHECK(counts.cache_lines == 4);
    counts.touch(memory + 32, 48);  // a binary leaf's triangle across a line boundary
    CHECK(counts.cache_lines == 6);
    counts.touch(memory + 63, 1);
    CHECK(counts.cache_lines == 7);
}

TEST_CASE("heatmaps hold what the counting kernel reports per pixel", "[render][heatmap]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=4");
    const FlatScene flat = flatten(scene);
    const PinholeCamera camera(*scene.camera, 40, 30);
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_heatmap.exr").string();
    const auto accel = built(make_canopy_accelerator(flat, {}));
    const HeatmapStats stats = write_heatmap(*accel, camera, 40, 30, path);
    auto in = OIIO::ImageInput::open(path);
    REQUIRE(in);
    CHECK(in->spec().channelnames == std::vector<std::string>{"inner", "leaves", "triangles"});
    std::vector<float> counts(40 * 30 * 3);
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, counts.data()));
    double inner = 0;
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 40; ++x) {
            const TraversalCounts c = accel->count(camera.generate(x, y, 0.5f, 0.5f));
            const float* p = &counts[size_t(y * 40 + x) * 3];
            CHECK(p[0] == float(c.inner_nodes));
            CHECK(p[1] == float(c.leaf_nodes));
            CHECK(p[2] == float(c.triangle_tests));
            inner += p[0];
        }
    CHECK(stats.mean_inner == Approx(inner / (40 * 30)));
    CHECK(stats.mean_inner >= 1.0);  // every ray tests the root
    CHECK(std::filesystem::exists(std::filesystem::path(path).replace_extension(".png")));
    const auto embree = built(make_embree_accelerator(flat, "medium", 0));
    CHECK_THROWS_WITH(write_heatmap(*embree, camera, 40, 30, path), Catch::Contains("canopy kernel"));
}

namespace {

// A machine and scene of known costs: what auto's calibration would measure, per candidate; what it built, traced
// and discarded, in order.
struct FixedCosts final : Calibration {
    struct Costs { double build_ms, frame_ms; };
    std::map<std::string, Costs> costs;  // by builder (flat) or "rebraid/binned"
    std::vector<std::string> built, discarded;
    double share = 0.01;
    std::string last;

    static std::string key(const std::string& builder, const std::string& toplevel) {
        return toplevel == "flat" ? builder : toplevel + "/" + builder;
    }
    double build(const std::string& builder, const std::string& toplevel) override {
        last = key(builder, toplevel);
        built.push_back(last);
        return costs.at(last).build_ms;
    }
    SampleReading sample_frame() override {
        const double frame = costs.at(last).frame_ms;
        return {frame * share, frame * share, frame};
    }
    TreeReading read_tree() override { return {overlap, 0.0}; }
    void discard(const std::string& builder, const std::string& toplevel) override { discarded.push_back(key(builder, toplevel)); }
    double sample_cost_ms(double frame_ms) const override { return frame_ms * share; }
    double overlap = -1.0;  // every tree's sibling overlap; negative: none kept
};

// Costs exactly as the priors predict them for these statistics.
FixedCosts prior_costs(const SceneStatistics& stats, int frames, uint64_t pixels) {
    FixedCosts fixed;
    for (const CandidateEstimate& c : prior_estimates(stats, frames, pixels))
        fixed.costs[FixedCosts::key(c.builder, c.toplevel)] = {c.build_ms, c.frame_ms};
    return fixed;
}

SceneStatistics sponza_statistics() {
    SceneStatistics s;
    s.triangles = s.unique_triangles = 262205;
    s.box_excess = 1.48, s.reducible_cover = 6.8, s.camera_inside = true, s.box_fill = 0.36;
    return s;
}

constexpr uint64_t kPixels = 1024 * 768;

}  // namespace

// What a sample costs auto in all: the measured candidates' samples.
double samples_ms(const AutoChoice& choice) {
    double sum = 0.0;
    for (const CandidateEstimate& c : choice.candidates) sum += c.sample_ms;
    return sum;
}

TEST_CASE("auto measures the predicted best first unless its extra build exceeds what it is predicted to save", "[auto]") {
    // A small scan seen from outside, planned for 16 frames: binned is predicted best, lbvh's frames 12% slower for a
    // build cheaper by far less than that; binned is measured first, and it wins.
    SceneStatistics scan;
    scan.triangles = scan.unique_triangles = 34594, scan.box_excess = 1.9, scan.reducible_cover = 2.0, scan.box_fill = 0.3;
    scan.projected_area = 0.36;
    const std::vector<CandidateEstimate> scan_prior = prior_estimates(scan, 16, kPixels);
    REQUIRE(scan_prior.front().builder == "binned");
    FixedCosts scanner = prior_costs(scan, 16, kPixels);
    CHECK(choose_builder(scan, 16, kPixels, scanner).builder == "binned");
    CHECK(scanner.built.front() == "binned");
    // A room planned for 20 frames: bittner is predicted best, by less than its build costs over binned's, the cheapest
    // build predicted within 10% of it, which is measured first.
    SceneStatistics room;
    room.triangles = room.unique_triangles = 331179;
    room.box_excess = 1.59, room.reducible_cover = 3.7, room.camera_inside = true, room.box_fill = 0.34;
    constexpr int kFrames = 20;
    const std::vector<CandidateEstimate> prior = prior_estimates(room, kFrames, kPixels);
    REQUIRE(prior.size() == 6);  // every flat candidate but esc, which splits nothing here; no top level
    for (size_t i = 1; i < prior.size(); ++i) CHECK(prior[i - 1].time_to_image_ms(kFrames) <= prior[i].time_to_image_ms(kFrames));
    REQUIRE(prior.front().builder == "bittner");
    const CandidateEstimate* first = &prior.front();
    for (const CandidateEstimate& c : prior)
        if (c.time_to_image_ms(kFrames) <= 1.1 * prior.front().time_to_image_ms(kFrames) && c.build_ms < first->build_ms) first = &c;
    REQUIRE(prior.front().build_ms - first->build_ms > first->time_to_image_ms(kFrames) - prior.front().time_to_image_ms(kFrames));
    // This "machine" traces sbvh's tree at half binned's frame, which no prior expects of an architectural scene.
    FixedCosts machine = prior_costs(room, kFrames, kPixels);
    machine.costs["sbvh"].frame_ms = 0.5 * machine.costs["binned"].frame_ms;
    const AutoChoice choice = choose_builder(room, kFrames, kPixels, machine);
    CHECK(machine.built.front() == first->builder);
    CHECK(choice.candidates.front().note.find("cheapest build") != std::string::npos);
    CHECK(choice.builder == "sbvh");
    CHECK(choice.toplevel == "flat");
    CHECK(std::find(machine.discarded.begin(), machine.discarded.end(), "sbvh") == machine.discarded.end());
    CHECK(machine.discarded.size() == machine.built.size() - 1);  // every tree but the winner's is let go
    for (const CandidateEstimate& c : choice.candidates)
        if (!c.measured) CHECK(c.note.find("not measured") != std::string::npos);
    CHECK(choice.reason.find("reducible cover 3.7") != std::string::npos);
    CHECK(choice.reason.find("20 frames planned: sbvh") != std::string::npos);
    // Its own time to image: every build and sample, and the winner's frames, its 8 ms sample's reading weighed
    // against the prior, which expects sbvh's frame no faster than binned's.
    double builds = 0.0;
    for (const CandidateEstimate& c : choice.candidates)
        if (c.measured) builds += c.build_ms;
    const auto winner = std::find_if(choice.candidates.begin(), choice.candidates.end(),
                                     [](const CandidateEstimate& c) { return c.builder == "sbvh"; });
    REQUIRE(winner != choice.candidates.end());
    CHECK(winner->sampled_frame_ms == Approx(machine.costs["sbvh"].frame_ms));
    CHECK(winner->sample_weight > 0.9);
    CHECK(winner->frame_ms > winner->sampled_frame_ms);
    CHECK(winner->frame_ms < 1.05 * winner->sampled_frame_ms);
    CHECK(choice.time_to_image_ms == Approx(builds + samples_ms(choice) + kFrames * winner->frame_ms));
}

// A scene of axis-aligned quads facing a camera at the origin that looks down -z with a 90-degree field of view,
// each quad spanning [x0, x1] of the image's width (-1 to 1) and all its height at depth `depth`.
static Scene facing_quads(const std::vector<std::array<float, 3>>& quads, double aspect) {
    Scene scene;
    Mesh mesh;
    for (const auto& [x0, x1, depth] : quads) {
        const float half_width = float(aspect) * depth, z = -depth;
        const auto base = uint32_t(mesh.positions.size());
        for (const float y : {-depth, depth})
            for (const float x : {x0 * half_width, x1 * half_width}) mesh.positions.push_back({x, y, z});
        mesh.triangles.push_back({base, base + 1, base + 3});
        mesh.triangles.push_back({base, base + 3, base + 2});
    }
    mesh.objects.push_back({"quads", 0, uint32_t(mesh.triangles.size())});
    scene.meshes.push_back(std::move(mesh));
    scene.instances.push_back({0, glm::mat4(1.0f)});
    scene.camera = Camera{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 90.0f};
    return scene;
}

TEST_CASE("projected area is the image's share the triangles cover, times their depth complexity", "[auto]") {
    constexpr double kAspect = 16.0 / 9.0;
    const auto projected = [&](const std::vector<std::array<float, 3>>& quads) {
        const Scene scene = facing_quads(quads, kAspect);
        return scene_statistics(scene, flatten(scene), kAspect).projected_area;
    };
    CHECK(projected({{-1, 1, 2}}) == Approx(1.0));                     // fills the image, at any depth
    CHECK(projected({{-1, 1, 1e4f}}) == Approx(1.0));
    CHECK(projected({{-1, 1, 1e11f}}) == Approx(1.0));                 // near the largest and smallest scenes
    CHECK(projected({{-1, 1, 1e-11f}}) == Approx(1.0));                // flatten() accepts (1e12, 1e-12)
    CHECK(projected({{-1, 0, 3}}) == Approx(0.5));                     // its left half
    CHECK(projected({{-1, 1, 2}, {-1, 1, 5}}) == Approx(2.0));         // two layers: depth complexity 2
    CHECK(projected({{-1, 1, -2}}) == 0.0);                            // behind the camera
    CHECK(projected({{1.5f, 2.5f, 2}}) == 0.0);                        // right of the view
}

TEST_CASE("auto expects an object's frame to cost by the share of the image it covers", "[auto]") {
    // A ship seen from outside, 99 k triangles on 9% of a one-frame image: its frame is cheap, so lbvh's cheaper build
    // is predicted to pay more than binned's tree saves, and lbvh is measured first. The same scan covering 73% of
    // the image (as the dragon does) is predicted to trace long enough for binned's tree to pay for its build.
    SceneStatistics ship;
    ship.triangles = ship.unique_triangles = 99160, ship.box_excess = 1.6, ship.reducible_cover = 2.0, ship.box_fill = 0.35;
    ship.projected_area = 0.09;
    CHECK(prior_estimates(ship, 1, kPixels).front().builder == "lbvh");
    FixedCosts machine = prior_costs(ship, 1, kPixels);
    CHECK(choose_builder(ship, 1, kPixels, machine).builder == "lbvh");
    CHECK(machine.built.front() == "lbvh");
    SceneStatistics covering = ship;
    covering.projected_area = 0.73;
    CHECK(prior_estimates(covering, 1, kPixels).front().builder == "binned");
    // Past the largest area the per-pixel cost was fitted on, it does not grow further.
    SceneStatistics deep = ship, deeper = ship;
    deep.projected_area = 2.1, deeper.projected_area = 40.0;
    CHECK(prior_estimates(deep, 1, kPixels).front().frame_ms == Approx(prior_estimates(deeper, 1, kPixels).front().frame_ms));
}

TEST_CASE("auto weighs a sample's reading against the priors by the sample's length", "[auto]") {
    // A small scan filling the image (its front and back faces: projected area 1.6) planned for one frame, traced
    // through one pixel in a thousand: lbvh's sample reads its frame at 0.9x binned's, where the priors expect 1.09x.
    // Every candidate but bittner fits the calibration budget.
    SceneStatistics scan;
    scan.triangles = scan.unique_triangles = 3732, scan.box_excess = 2.05, scan.reducible_cover = 2.0, scan.box_fill = 0.35;
    scan.projected_area = 1.6;
    const auto choose = [&](uint64_t pixels) {
        FixedCosts machine = prior_costs(scan, 1, pixels);
        machine.costs["lbvh"].frame_ms = 0.9 * machine.costs["binned"].frame_ms;
        machine.share = 0.001;
        const AutoChoice choice = choose_builder(scan, 1, pixels, machine);
        CHECK(std::find(machine.built.begin(), machine.built.end(), "lbvh") != machine.built.end());
        return choice.builder;
    };
    CHECK(sample_weight(0.15) < 0.5);
    CHECK(choose(kPixels) == "binned");       // samples of 0.16 ms: the priors outweigh them
    CHECK(sample_weight(4.0) > 0.9);
    CHECK(choose(30 * kPixels) == "lbvh");    // 4.7 ms: the reading outweighs the priors
}

TEST_CASE("sbvh's predicted frame falls with binned's sibling overlap, down to its floor", "[auto]") {
    CHECK(sbvh_frame_from_overlap(0.0) == 1.0);
    CHECK(sbvh_frame_from_overlap(0.17) == 1.0);
    CHECK(sbvh_frame_from_overlap(0.18) < 1.0);
    CHECK(sbvh_frame_from_overlap(0.215) < sbvh_frame_from_overlap(0.18));
    CHECK(sbvh_frame_from_overlap(0.2) == Approx(0.886));
    CHECK(sbvh_frame_from_overlap(0.5) == Approx(0.83));  // no extrapolation past the largest gain fitted
}

TEST_CASE("auto judges sbvh by the sibling overlap of binned's tree, once binned is measured", "[auto]") {
    // sibenik's statistics planned for one frame: architecture without dense boxes, where the class prior expects
    // sbvh to trace as fast as binned; on this machine it traces in 0.92x.
    SceneStatistics room;
    room.triangles = room.unique_triangles = 75284, room.box_excess = 1.61, room.reducible_cover = 3.6;
    room.box_fill = 0.36, room.camera_inside = true;
    const auto choose = [&](double overlap) {
        FixedCosts machine = prior_costs(room, 1, kPixels);
        machine.costs["sbvh"].frame_ms = 0.92 * machine.costs["binned"].frame_ms;
        machine.overlap = overlap;
        const AutoChoice choice = choose_builder(room, 1, kPixels, machine);
        CHECK(machine.built.front() == "binned");
        CHECK(choice.sibling_overlap == overlap);
        return choice;
    };
    // No tree to read, or one whose siblings overlap as little as conference's: the build is not worth its
    // predicted gain, nor within the budget.
    CHECK(choose(-1.0).builder == "binned");
    CHECK(choose(0.16).builder == "binned");
    // Siblings that overlap as much as crytek-sponza's: sbvh is measured, and wins.
    const AutoChoice overlapping = choose(0.215);
    CHECK(overlapping.builder == "sbvh");
    CHECK(overlapping.reason.find("sibling overlap 0.215") != std::string::npos);
    // Sliver fields keep their class priors: the overlap is not read.
    SceneStatistics slivers = room;
    slivers.box_excess = 6.75;
    FixedCosts machine = prior_costs(slivers, 1, kPixels);
    machine.overlap = 0.215;
    CHECK(choose_builder(slivers, 1, kPixels, machine).sibling_overlap < 0.0);
}

TEST_CASE("auto stays within 10% of the best time to image when the priors hold", "[auto]") {
    const SceneStatistics sponza = sponza_statistics();
    for (const int frames : {1, 16, 256}) {
        FixedCosts machine = prior_costs(sponza, frames, kPixels);
        const AutoChoice choice = choose_builder(sponza, frames, kPixels, machine);
        const CandidateEstimate best = prior_estimates(sponza, frames, kPixels).front();
        CAPTURE(frames, choice.builder, best.builder);
        CHECK(choice.time_to_image_ms <= 1.1 * best.time_to_image_ms(frames));
        CHECK(choice.calibration_ms <= choice.budget_ms + samples_ms(choice) + best.build_ms);
    }
    // One frame: bittner's second-long build can neither pay for itself nor fit the budget, so it is never built.
    FixedCosts machine = prior_costs(sponza, 1, kPixels);
    choose_builder(sponza, 1, kPixels, machine);
    CHECK(std::find(machine.built.begin(), machine.built.end(), "bittner") == machine.built.end());
    // 256 frames: the budget is seconds, and every candidate is measured.
    machine = prior_costs(sponza, 256, kPixels);
    choose_builder(sponza, 256, kPixels, machine);
    CHECK(machine.built.size() == 6);
}

TEST_CASE("auto splits where splitting pays on this machine, not where the statistics alone say so", "[auto]") {
    // Slivers (the foliage's statistics): the priors expect splits to pay 2.7x.
    SceneStatistics foliage;
    foliage.triangles = foliage.unique_triangles = 48000, foliage.box_excess = 24.0, foliage.reducible_cover = 54.1;
    foliage.box_fill = 0.031;
    FixedCosts no_gain = prior_costs(foliage, 256, kPixels);
    for (const char* split : {"sbvh", "esc", "bonsai-split"}) no_gain.costs[split].frame_ms = 1.2 * no_gain.costs["binned"].frame_ms;
    // At 256 frames every candidate is measured: the least frame wins, a tree that splits nothing (bittner's, 0.87x).
    const std::string chosen = choose_builder(foliage, 256, kPixels, no_gain).builder;
    CHECK(chosen == "bittner");
    for (const auto& [name, costs] : no_gain.costs) CHECK(no_gain.costs[chosen].frame_ms <= costs.frame_ms);
    // Where they do pay, the one with the best frame wins many frames.
    FixedCosts gain = prior_costs(foliage, 256, kPixels);
    gain.costs["sbvh"].frame_ms = 0.9 * gain.costs["esc"].frame_ms;
    CHECK(choose_builder(foliage, 256, kPixels, gain).builder == "sbvh");
    FixedCosts one = prior_costs(foliage, 1, kPixels);
    CHECK(choose_builder(foliage, 1, kPixels, one).time_to_image_ms <= 1.1 * prior_estimates(foliage, 1, kPixels).front().time_to_image_ms(1));
}

TEST_CASE("auto expects esc to lead where slivers cross the scene, and sbvh where they cluster", "[auto]") {
    const auto fastest_frame = [](const Scene& scene) {
        const std::vector<CandidateEstimate> candidates = prior_estimates(scene_statistics(scene, flatten(scene), 4.0 / 3.0), 256, kPixels);
        return std::min_element(candidates.begin(), candidates.end(), [](const CandidateEstimate& a, const CandidateEstimate& b) {
                   return a.frame_ms < b.frame_ms;
               })->builder;
    };
    for (const char* crossing : {"gen:cylinders?tris=3000&seed=2", "gen:cylinders?tris=50000&seed=7"})
        CHECK(fastest_frame(load_scene(crossing)) == "esc");
    for (const char* clustered : {"gen:foliage?tris=3000&seed=2", "gen:foliage?tris=48000&seed=4"})
        CHECK(fastest_frame(load_scene(clustered)) == "sbvh");
}

TEST_CASE("auto measures esc only where its automatic SA_max splits", "[auto]") {
    const auto has_esc = [](const SceneStatistics& stats) {
        const std::vector<CandidateEstimate> candidates = prior_estimates(stats, 16, kPixels);
        return std::any_of(candidates.begin(), candidates.end(), [](const CandidateEstimate& c) { return c.builder == "esc"; });
    };
    SceneStatistics stats = sponza_statistics();
    CHECK_FALSE(has_esc(stats));
    stats.box_fill = 0.099;
    CHECK(has_esc(stats));
    // The statistics' fill is the one esc's rule reads: generated slivers split, a generated room does not.
    const Scene foliage = load_scene("gen:foliage?tris=3000&seed=2"), room = load_scene("gen:room?tris=3000&seed=2");
    CHECK(scene_statistics(foliage, flatten(foliage), 4.0 / 3.0).box_fill < kEscMaxFillToSplit);
    CHECK(scene_statistics(room, flatten(room), 4.0 / 3.0).box_fill > kEscMaxFillToSplit);
    const FlatScene flat = flatten(foliage);
    CHECK(std::isfinite(automatic_sa_max(flat.triangles, make_prim_refs(flat.triangles))));
}

TEST_CASE("auto chooses two-level only with instances, and only two-level past the flattening limit", "[auto]") {
    SceneStatistics zoo = sponza_statistics();
    zoo.unique_triangles = 150000, zoo.triangles = 64 * zoo.unique_triangles, zoo.camera_inside = false;
    const std::vector<CandidateEstimate> zoo_candidates = prior_estimates(zoo, 16, kPixels);
    CHECK(std::any_of(zoo_candidates.begin(), zoo_candidates.end(), [](const CandidateEstimate& c) { return c.toplevel == "rebraid"; }));
    FixedCosts machine = prior_costs(zoo, 16, kPixels);
    CHECK(choose_builder(zoo, 16, kPixels, machine).toplevel == "rebraid");
    zoo.triangles = 1024 * zoo.unique_triangles;  // 150 M triangles flattened: past the limit
    const std::vector<CandidateEstimate> only = prior_estimates(zoo, 1, kPixels);
    REQUIRE(only.size() == 1);
    CHECK(only.front().toplevel == "rebraid");
    for (const CandidateEstimate& c : prior_estimates(sponza_statistics(), 1, kPixels)) CHECK(c.toplevel == "flat");
    // The same rule decides whether auto prepares PrimRefs for a flat candidate at all.
    CHECK_FALSE(flat_candidates(zoo.triangles, zoo.unique_triangles));
    CHECK(flat_candidates(64 * zoo.unique_triangles, zoo.unique_triangles));
    CHECK(flat_candidates(2 * kMaxFlattenedTriangles, 2 * kMaxFlattenedTriangles));  // nothing instanced: flat only
}

TEST_CASE("auto's explanation lists every candidate and the choice", "[auto]") {
    const SceneStatistics sponza = sponza_statistics();
    FixedCosts machine = prior_costs(sponza, 16, kPixels);
    const AutoChoice choice = choose_builder(sponza, 16, kPixels, machine);
    const std::string text = explain(choice, 16);
    for (const CandidateEstimate& c : choice.candidates) CHECK(text.find(c.note) != std::string::npos);
    CHECK(choice.candidates.size() == 6);
    CHECK(text.find("chosen: " + choice.builder) != std::string::npos);
    CHECK(text.find("TTI@16") != std::string::npos);
}

TEST_CASE("auto's budget counts a sample's warm-up and its retrace where the first trace is too short to time", "[auto]") {
    // Every sample after the first tree's is preceded by a warm-up of one tile in kTreeWarmUpStride.
    const auto warm_up = [](double frame_ms) { return frame_ms / kTreeWarmUpStride; };
    // forklift at 16 frames: a 30 ms frame, one tile in 32 (0.94 ms), then the retrace of 6.25 ms.
    CHECK(expected_sample_cost_ms(30.0, 32, 5.0) == Approx(warm_up(30.0) + 30.0 / 32 + kSampleAim * 5.0));
    // A first trace long enough is all of it but the warm-up; so is one with no minimum (one frame planned).
    CHECK(expected_sample_cost_ms(400.0, 32, 5.0) == Approx(warm_up(400.0) + 12.5));
    CHECK(expected_sample_cost_ms(30.0, 128, 0.0) == Approx(warm_up(30.0) + 30.0 / 128));
    // The retrace is at least twice the first, and at most the whole frame.
    CHECK(expected_sample_cost_ms(150.0, 32, 5.0) == Approx(warm_up(150.0) + 3.0 * 150.0 / 32));
    CHECK(expected_sample_cost_ms(4.0, 32, 5.0) == Approx(warm_up(4.0) + 4.0 / 32 + 4.0));
    CHECK(expected_sample_cost_ms(4.0, 1, 5.0) == Approx(warm_up(4.0) + 4.0));
}

TEST_CASE("a sample too short to time is traced again with as many tiles as its rate says it needs", "[auto]") {
    // 0.9 ms through one tile in 32, where 5 ms are needed: 32 x 0.9 / 6.25 = 4.6, so one tile in 4 (about 7 ms).
    CHECK(next_sample_stride(32, 0.9, 5.0) == 4);
    // At least twice the tiles, however close the sample came, and never fewer.
    CHECK(next_sample_stride(32, 4.9, 5.0) == 16);
    CHECK(next_sample_stride(32, 5.0 * kSampleAim, 5.0) == 16);
    // A sample that took no time, or a negative clock difference, asks for the whole frame; so does a stride of 1.
    CHECK(next_sample_stride(128, 0.0, 5.0) == 1);
    CHECK(next_sample_stride(128, -1.0, 5.0) == 1);
    CHECK(next_sample_stride(1, 0.1, 5.0) == 1);
    CHECK(next_sample_stride(2, 0.1, 5.0) == 1);
    // A rate that needs exactly one tile in 8 gets it.
    CHECK(next_sample_stride(128, 8.0 * kSampleAim * 5.0 / 128.0, 5.0) == 8);
}

TEST_CASE("a frame's sample traces the frame's own paths in its tiles, and nothing else", "[auto]") {
    const Scene scene = load_scene("gen:box?tris=2000&seed=3");
    const FlatScene flat = flatten(scene);
    const auto accel = make_canopy_accelerator(scene, flat, CanopyOptions{});
    accel->prepare();
    accel->build();
    FrameSettings whole_frame, sample;
    whole_frame.width = sample.width = 45, whole_frame.height = sample.height = 30;  // tiles cut by both edges
    sample.sample_stride = 4;
    const PinholeCamera camera(scene_camera(scene, flat), 45, 30);
    Image whole(45, 30), sampled(45, 30);
    accel->render(ShadingScene{flat, whole_frame}, camera, 3, whole);
    accel->render(ShadingScene{flat, sample}, camera, 3, sampled);
    // A tile in 4 of the 6 x 4 tiles of 8 x 8 pixels: one in each run of 4, the edge tiles cut to the frame.
    std::set<std::pair<int, int>> in_sample;
    for (uint64_t k = 0; k < 6; ++k) {
        const uint64_t tile = sample_tile(k, 4);
        CHECK(tile / 4 == k);
        for (int y = 8 * int(tile / 6); y < std::min(8 * int(tile / 6) + 8, 30); ++y)
            for (int x = 8 * int(tile % 6); x < std::min(8 * int(tile % 6) + 8, 45); ++x) in_sample.insert({x, y});
    }
    CHECK(traced_pixels(45, 30, 4) == in_sample.size());
    CHECK(traced_pixels(45, 30, 1) == 45u * 30u);
    const std::vector<float> all = whole.average(1), part = sampled.average(1);
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 45; ++x)
            for (int c = 0; c < 3; ++c) {
                const size_t i = (size_t(y) * 45 + size_t(x)) * 3 + size_t(c);
                CHECK(part[i] == (in_sample.count({x, y}) ? all[i] : 0.0f));
            }
}

TEST_CASE("auto builds the tree it chose on the machine at hand", "[auto]") {
    // The choice is a registered builder, and the accelerator built with it reports it.
    const Scene scene = load_scene("gen:box?tris=2000&seed=3");
    const FlatScene flat = flatten(scene);
    CanopyOptions options;
    options.builder = "auto";
    const auto accel = make_canopy_accelerator(scene, flat, options);
    accel->prepare();
    accel->build();
    CHECK(accel->builder() == "auto");
    const std::string chosen = accel->chosen();  // an optimiser names its start tree: "bittner<lbvh"
    CHECK_NOTHROW(find_builder(chosen.substr(0, chosen.find('<'))));
    CHECK_THROWS_WITH(make_canopy_accelerator(flat, options), Catch::Contains("auto"));
}
