// A standalone path tracer on Intel Embree 3 alone, written as an Embree user would write one: the benchmark
// protocol's camera, random numbers and diffuse shading (../shared/BENCHMARK.md), Embree's rtcIntersect1 for every
// ray, and shading from Embree's hit record (Ng, t, primID) without reading the scene's triangles. It shares no
// accelerator or path tracer code with canopy, only the scene loader, the camera and the sampling helpers, so that its
// rays are canopy's Embree row's: what that row's frame time must match.
#include "renderer/camera.h"
#include "renderer/sampling.h"
#include "scenes/scene.h"
#include "tools/embree_scene.h"

#include <CLI/CLI.hpp>
#include <embree3/rtcore.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <memory>
#include <stdexcept>
#include <vector>

namespace {

using canopy::Ray;
using canopy::Rng;
using canopy::Vec3;

constexpr int kMaxBounces = 8;  // the protocol's: at most 9 closest-hit rays per path
constexpr float kAlbedo = 0.8f;
constexpr int kTile = 16;       // square tiles of pixels, one TBB task each

struct Options {
    std::string scene;
    std::vector<int> size{1024, 768};
    int frames = 10;
    int threads = 0;
};

RTCRayHit closest_hit(RTCScene scene, const Ray& ray) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    // RTCRay's members in declaration order: origin, tnear, direction, time, tfar, mask, id, flags.
    RTCRayHit rh{};
    rh.ray = RTCRay{ray.org.x, ray.org.y, ray.org.z, 0.0f, ray.dir.x, ray.dir.y, ray.dir.z, 0.0f,
                    std::numeric_limits<float>::infinity(), 0xffffffffu, 0, 0};
    rh.hit.geomID = rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, &context, &rh);
    return rh;
}

// One path of the protocol from the camera ray: white sky on a miss, the albedo on every hit, the next ray from the
// hit point along the ray, pushed off the surface, in a cosine-weighted direction about the normal facing the ray.
Vec3 trace_path(RTCScene scene, Ray ray, Rng& rng, uint64_t& rays) {
    Vec3 throughput(1.0f), radiance(0.0f);
    for (int depth = 0;; ++depth) {
        ++rays;
        const RTCRayHit rh = closest_hit(scene, ray);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
            radiance += throughput;
            break;
        }
        Vec3 n(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
        const float len2 = glm::dot(n, n);
        n = len2 > 0.0f && std::isfinite(len2) ? n / std::sqrt(len2) : -ray.dir;
        if (glm::dot(n, ray.dir) > 0.0f) n = -n;
        throughput *= Vec3(kAlbedo);
        if (depth == kMaxBounces) break;
        const Vec3 p = ray.org + rh.ray.tfar * ray.dir;
        ray.org = canopy::offset_ray_origin(p, n, canopy::ray_point_error(p, rh.ray.tfar));
        ray.dir = canopy::cosine_direction(n, rng.next_float(), rng.next_float());
    }
    return radiance;
}

struct FrameResult {
    uint64_t rays = 0;
    double radiance = 0;  // summed over pixels and channels
};

// One sample per pixel of frame `frame`, each pixel's random numbers seeded by its index and the frame.
FrameResult render_frame(RTCScene scene, const canopy::PinholeCamera& camera, int w, int h, uint32_t frame) {
    const int tiles_x = (w + kTile - 1) / kTile, tiles = tiles_x * ((h + kTile - 1) / kTile);
    std::vector<FrameResult> per_tile(static_cast<size_t>(tiles));
    tbb::parallel_for(0, tiles, [&](int tile) {
        FrameResult& r = per_tile[size_t(tile)];
        const int x0 = tile % tiles_x * kTile, y0 = tile / tiles_x * kTile;
        for (int y = y0; y < std::min(y0 + kTile, h); ++y) {
            for (int x = x0; x < std::min(x0 + kTile, w); ++x) {
                Rng rng(uint64_t(y) * uint64_t(w) + uint64_t(x), frame);
                const float u = rng.next_float(), v = rng.next_float();
                const Vec3 c = trace_path(scene, camera.generate(x, y, u, v), rng, r.rays);
                r.radiance += double(c.x) + double(c.y) + double(c.z);
            }
        }
    });
    FrameResult total;
    for (const FrameResult& r : per_tile) total.rays += r.rays, total.radiance += r.radiance;
    return total;
}

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// As canopy's bench: one untimed warm-up frame (frame 0), then frames 1..N timed.
int run(const Options& o) {
    const canopy::Scene loaded = canopy::load_scene(o.scene);
    const canopy::FlatScene flat = canopy::flatten(loaded);
    std::unique_ptr<tbb::global_control> limit;
    if (o.threads > 0) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(o.threads));
    const auto build_start = std::chrono::steady_clock::now();
    const canopy::tools::EmbreeScene embree(flat, o.threads);
    const double build_ms = ms_since(build_start);
    const int w = o.size[0], h = o.size[1];
    const canopy::PinholeCamera camera(canopy::scene_camera(loaded, flat), w, h);
    render_frame(embree.scene(), camera, w, h, 0);
    FrameResult all;
    double frames_ms = 0;
    for (int frame = 1; frame <= o.frames; ++frame) {
        const auto start = std::chrono::steady_clock::now();
        const FrameResult r = render_frame(embree.scene(), camera, w, h, uint32_t(frame));
        frames_ms += ms_since(start);
        all.rays += r.rays, all.radiance += r.radiance;
    }
    std::printf("scene %s: %zu triangles, %d x %d, %d frames after a warm-up, %s\n", o.scene.c_str(), flat.triangles.size(), w, h,
                o.frames, o.threads > 0 ? (std::to_string(o.threads) + " threads").c_str() : "all threads");
    std::printf("build ms %.2f\n", build_ms);
    std::printf("frame ms %.2f\n", frames_ms / o.frames);
    std::printf("rays/frame %.1f\n", double(all.rays) / o.frames);
    std::printf("image mean %.6f\n", all.radiance / (3.0 * double(w) * double(h) * o.frames));
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"The benchmark protocol's path tracer on Embree alone (MEDIUM quality, rtcIntersect1)"};
    Options o;
    app.add_option("scene", o.scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    app.add_option("--size", o.size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    app.add_option("--frames", o.frames, "Timed frames, after one warm-up frame")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    app.add_option("--threads", o.threads, "Threads for TBB and Embree (0: all)")->check(CLI::Range(0, 4096))->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    try {
        return run(o);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "embree_path_tracer: %s\n", e.what());
        return 1;
    }
}
