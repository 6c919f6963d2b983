// The benchmark protocol's camera, path tracer, ray offset, EXR output and bench report.
#include "oracle.h"
#include "experiments/embree_accelerator.h"
#include "renderer/frames.h"
#include "experiments/bench.h"
#include "engine/auto_builder.h"
#include "accel/builders/early_split_clipping.h"
#include "renderer/heatmap.h"

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
    const uint64_t rays = render(accel, shading, PinholeCamera(cam, w, h), 0, image);
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
    flat.triangles = cube_inside();
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
    write_image(path, 8, 4, rgb);
    auto in = OIIO::ImageInput::open(path);
    REQUIRE(in);
    CHECK(in->spec().width == 8);
    CHECK(in->spec().nchannels == 3);
    std::vector<float> back(rgb.size());
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, back.data()));
    CHECK(back == rgb);
    CHECK_THROWS_WITH(write_image("/nonexistent-dir/x.exr", 8, 4, rgb), Catch::Contains("/nonexistent-dir/x.exr"));
    CHECK(read_exr(path, 8, 4) == rgb);  // the tradeoff command's cached reference
    CHECK_THROWS_WITH(read_exr(path, 4, 8), Catch::Contains("expected 4x8"));
}

namespace {

// The 8-bit code values of the first pixel of an image file.
std::vector<int> first_pixel_codes(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    REQUIRE(in);
    std::vector<unsigned char> pixels(size_t(in->spec().image_pixels()) * 3);
    REQUIRE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, pixels.data()));
    return {pixels[0], pixels[1], pixels[2]};
}

}  // namespace

TEST_CASE("PNG and JPEG output carries the sRGB curve, EXR stays linear", "[render]") {
    // Linear 0.5 is sRGB 0.7354, code 188 of 255; written linearly it would be 128. JPEG is lossy: within 2.
    for (const char* name : {"canopy_test_srgb.png", "canopy_test_srgb.JPG"}) {
        const std::string path = (std::filesystem::temp_directory_path() / name).string();
        write_image(path, 8, 4, std::vector<float>(8 * 4 * 3, 0.5f));
        CAPTURE(name);
        for (int code : first_pixel_codes(path)) CHECK(std::abs(code - 188) <= 2);
    }
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_clamped.png").string();
    std::vector<float> rgb(8 * 4 * 3, 0.5f);
    rgb[0] = 2.0f, rgb[1] = -1.0f;  // beyond the range: clamped, not wrapped
    write_image(path, 8, 4, rgb);
    CHECK(first_pixel_codes(path) == std::vector<int>{255, 0, 188});
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
        const uint64_t rays = render(*accel, shading, camera, 1, image);
        const auto [counts, counted_rays] = count_frame(*accel, shading, camera, 1);
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
