#pragma once
// The benchmark protocol's diffuse path tracer (../shared/BENCHMARK.md) over TBB tiles, written once
// for any tracer type with `bool closest(const Ray&, Hit&) const`, so that canopy's kernels and Embree
// are driven by identical code and identical random numbers.
#include "kernels/traverse_stream.h"
#include "renderer/camera.h"
#include "renderer/image.h"
#include "renderer/lights.h"
#include "renderer/sampling.h"
#include "renderer/stream_choice.h"
#include "scenes/scene.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <functional>
#include <memory>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy {

// How a frame's paths meet the accelerator: one path at a time to its end (`single`, the protocol's reference), or
// every path of a batch one bounce at a time, each bounce's rays traced as one sorted batch (`stream`, wavefront.h).
enum class TracerKind { Single, Stream };

// The rays a frame traces (docs/workloads.md): the protocol's diffuse paths; one closest-hit camera ray a pixel;
// diffuse paths with next-event estimation, a shadow ray (any hit) to a light at each bounce; or a camera ray and
// ambient-occlusion rays (any hit) from its hit.
enum class Workload { Diffuse, Camera, Nee, Ao };
inline const char* workload_name(Workload workload) {
    constexpr const char* kNames[] = {"diffuse", "camera", "nee", "ao"};
    return kNames[int(workload)];
}
inline Workload parse_workload(const std::string& name) {
    for (Workload w : {Workload::Diffuse, Workload::Camera, Workload::Nee, Workload::Ao})
        if (name == workload_name(w)) return w;
    throw std::invalid_argument("unknown workload '" + name + "' (known: diffuse, camera, nee, ao)");
}
inline constexpr const char* kWorkloadHelp =
    "Rays traced: diffuse (the protocol's paths), camera (one closest-hit ray a pixel), nee (paths with a shadow ray "
    "to a light at each bounce, weighed by multiple importance sampling), ao (a camera ray and --ao-rays occlusion "
    "rays from its hit)";

struct FrameSettings {
    int width = 1024, height = 768;
    TracerKind tracer = TracerKind::Single;
    // stream: paths in flight per batch at most (each batch on one thread). Larger batches sort into more coherent
    // rays, and past this size gain little for their memory (docs/results.md#tracers-single-and-stream).
    uint32_t stream_paths = 1u << 18;
    BatchTraversal batch_traversal = BatchTraversal::Packet;  // stream: how canopy's kernels trace a batch
    StreamBatching stream_batching = StreamBatching::Measured;  // stream: each batch as a wavefront or path by path
    bool embree_packets = false;  // stream: Embree's batches in rtcIntersect16 packets, not through rtcIntersect1M
    int max_bounces = 8;           // at most max_bounces + 1 closest-hit rays per path
    // The single tracer traces only a sample of the frame's pixels, one 8 x 8 tile in each `sample_stride` (1: the
    // whole frame): what `--builder auto` times its candidates with.
    uint32_t sample_stride = 1;
    bool material_albedo = false;  // protocol: albedo 0.8 everywhere unless the scene asks for Kd
    float albedo = 0.8f;
    Workload workload = Workload::Diffuse;
    int ao_rays = 4;         // ao: occlusion rays from each camera hit
    float ao_length = 0.0f;  // ao: their length; 0 for a tenth of the scene box's diagonal
};

struct StreamStats;

struct ShadingScene {
    const FlatScene& flat;
    const FrameSettings& settings;
    StreamStats* stream_stats = nullptr;  // the stream tracer's sort time and memory, when the caller wants them
    // The stream tracer's choice of each batch's way, learned over the frames rendered with this ShadingScene.
    std::shared_ptr<StreamChooser> stream_chooser = std::make_shared<StreamChooser>();
    // Decided once per frame, so that the protocol's paths (no --materials) and scenes without lights pay one
    // predictable branch per bounce and add nothing to their radiance.
    bool emitters = settings.material_albedo && flat.has_emitters;
    // nee: the scene's emitters, or the sun where there are none.
    std::shared_ptr<const Lights> lights = settings.workload == Workload::Nee ? std::make_shared<Lights>(flat, emitters) : nullptr;
    float ao_length = settings.ao_length > 0.0f ? settings.ao_length : 0.1f * glm::length(flat.bounds.upper - flat.bounds.lower);

    Vec3 albedo(uint32_t prim) const {
        if (settings.material_albedo && !flat.material.empty()) return flat.materials[flat.material[prim]].kd;
        return Vec3(settings.albedo);
    }
    Vec3 emission(uint32_t prim) const { return flat.materials[flat.material[prim]].emission; }
};

// A path's state between bounces: what it carries, what it has gathered, and its random numbers.
struct PathState {
    Vec3 throughput{1.0f}, radiance{0.0f};
};

// What shading reads of a hit, filled in by each tracer from what it has at hand, so that no tracer pays for what
// another needs: canopy's from the hit triangle's corners, Embree's from its hit record alone.
struct SurfaceHit {
    Vec3 normal;        // the geometric normal, of any length and facing either side
    Vec3 point;         // the hit point
    float point_error;  // how far `point` may lie off the surface: added to the next ray's offset
    uint32_t prim;      // the flat scene's triangle id: its material
};

// A hit from its triangle's corners: the point from the barycentrics, whose error scales with the corners.
inline SurfaceHit triangle_surface(const Triangle& tri, const Hit& hit) {
    return {geometric_normal(tri), tri.v0 + hit.u * (tri.v1 - tri.v0) + hit.v * (tri.v2 - tri.v0),
            triangle_point_error(tri), hit.prim};
}

// A hit from the ray's distance and the normal the intersector reported, as an Embree user shades: the point along
// the ray, no triangle read.
inline SurfaceHit ray_surface(const Ray& ray, float t, const Vec3& normal, uint32_t prim) {
    const Vec3 p = ray.org + t * ray.dir;
    return {normal, p, ray_point_error(p, t), prim};
}

// The hit's unit normal, turned to face the ray (the ray's reverse where the triangle has no normal).
[[gnu::always_inline]] inline Vec3 facing_normal(const Ray& ray, const SurfaceHit& surface) {
    Vec3 n = surface.normal;
    const float len2 = glm::dot(n, n);
    n = len2 > 0.0f && std::isfinite(len2) ? n / std::sqrt(len2) : -ray.dir;
    return glm::dot(n, ray.dir) > 0.0f ? -n : n;
}

// One bounce's shading, shared by every tracer so that `single` and `stream` paths mean the same: a miss adds the
// white sky and ends the path; a hit adds what its material emits (under --materials; no next-event estimation),
// takes the albedo and, unless `depth` was the last bounce, turns `ray` into the next bounce's ray. Returns whether
// the path goes on. `surface` is read only when `found`.
[[gnu::always_inline]] inline bool shade_bounce(const ShadingScene& scene, const Ray& ray, bool found, const SurfaceHit& surface,
                                                int depth, PathState& path, Rng& rng, Ray& next) {
    if (!found) {
        path.radiance += path.throughput;  // white sky
        return false;
    }
    const Vec3 n = facing_normal(ray, surface);
    if (scene.emitters) path.radiance += path.throughput * scene.emission(surface.prim);
    path.throughput *= scene.albedo(surface.prim);
    if (depth == scene.settings.max_bounces) return false;
    // Written member by member, not as next = Ray{...}: GCC built that temporary with small stores and copied it
    // with one 32-byte load, which waited for them: a failed store forward that stalled canopy's kernels, which read
    // the ray from memory (docs/results.md#traversal-kernels; Embree's copy reads the members one by one).
    next.org = offset_ray_origin(surface.point, n, surface.point_error);
    next.dir = cosine_direction(n, rng.next_float(), rng.next_float());
    next.tmin = 0.0f;
    next.tmax = std::numeric_limits<float>::infinity();
    return true;
}

// One closest-hit query of a single-ray tracer and what shading reads of its hit, by the cheapest means the tracer
// offers: its own SurfaceHit (Embree's hit record), the hit triangle's corners from the leaf it read (canopy's flat
// trees), or else the scene's copy of the hit triangle.
template <class Tracer>
[[gnu::always_inline]] inline bool closest_surface(const Tracer& tracer, const ShadingScene& scene, const Ray& ray,
                                                   SurfaceHit& surface) {
    if constexpr (requires { tracer.closest(ray, surface); }) {
        return tracer.closest(ray, surface);
    } else if constexpr (requires(Hit& hit, Triangle& corners) { tracer.closest(ray, hit, corners); }) {
        Hit hit;
        Triangle corners;
        if (!tracer.closest(ray, hit, corners)) return false;
        surface = triangle_surface(corners, hit);
        return true;
    } else {
        Hit hit;
        if (!tracer.closest(ray, hit)) return false;
        surface = triangle_surface(scene.flat.triangles[hit.prim], hit);
        return true;
    }
}

// One path from its first ray; `ray` then holds each bounce's ray in turn. By reference, so the caller's ray is the
// one traced, not a copy.
template <class Tracer>
Vec3 trace_path(const Tracer& tracer, const ShadingScene& scene, Ray& ray, Rng& rng, uint64_t& rays) {
    PathState path;
    for (int depth = 0;; ++depth) {
        ++rays;
        SurfaceHit surface;
        const bool found = closest_surface(tracer, scene, ray, surface);
        if (!shade_bounce(scene, ray, found, surface, depth, path, rng, ray)) break;
    }
    return path.radiance;
}

// A tracer's any-hit query: its own (Embree's rtcOccluded1), the kernel's any-hit traversal, or else (tests' oracles)
// whether it finds a closest hit within the ray's interval.
template <class Tracer>
[[gnu::always_inline]] inline bool occluded(const Tracer& tracer, const Ray& ray) {
    Hit hit;
    if constexpr (requires { tracer.occluded(ray); }) return tracer.occluded(ray);
    else if constexpr (requires { tracer.template query<Query::Any>(ray, hit); }) return tracer.template query<Query::Any>(ray, hit);
    else return tracer.closest(ray, hit);
}

// The ray leaving a hit along `dir`, up to `tmax`.
inline Ray leaving_ray(const SurfaceHit& surface, const Vec3& n, const Vec3& dir, float tmax) {
    Ray ray;
    ray.org = offset_ray_origin(surface.point, n, surface.point_error);
    ray.dir = dir;
    ray.tmin = 0.0f;
    ray.tmax = tmax;
    return ray;
}

// `camera`: the camera ray's closest hit lit from the eye (albedo times the cosine to the ray, plus emission); the
// white sky on a miss.
inline Vec3 camera_radiance(const ShadingScene& scene, const Ray& ray, bool found, const SurfaceHit& surface) {
    if (!found) return Vec3(1.0f);
    const Vec3 lit = scene.albedo(surface.prim) * -glm::dot(facing_normal(ray, surface), ray.dir);
    return scene.emitters ? lit + scene.emission(surface.prim) : lit;
}

template <class Tracer>
Vec3 trace_camera(const Tracer& tracer, const ShadingScene& scene, const Ray& ray, uint64_t& rays) {
    ++rays;
    SurfaceHit surface;
    const bool found = closest_surface(tracer, scene, ray, surface);
    return camera_radiance(scene, ray, found, surface);
}

// `ao`: settings.ao_rays cosine-weighted rays of length ao_length from a camera ray's hit, each made by ao_probe from
// the first, ao_base; the share of them that reach nothing is the pixel's value (the white sky's irradiance there
// over pi), 1 on a miss.
inline Ray ao_base(const ShadingScene& scene, const Ray& ray, const SurfaceHit& surface) {
    const Vec3 n = facing_normal(ray, surface);
    return leaving_ray(surface, n, n, scene.ao_length);
}
inline Ray ao_probe(const Ray& base, Rng& rng) {
    Ray probe = base;
    probe.dir = cosine_direction(base.dir, rng.next_float(), rng.next_float());
    return probe;
}
inline Vec3 ao_radiance(int open, int probes) { return Vec3(float(open) / float(probes)); }

template <class Tracer>
Vec3 trace_ao(const Tracer& tracer, const ShadingScene& scene, const Ray& ray, Rng& rng, uint64_t& rays) {
    ++rays;
    SurfaceHit surface;
    if (!closest_surface(tracer, scene, ray, surface)) return Vec3(1.0f);
    const Ray base = ao_base(scene, ray, surface);
    const int count = scene.settings.ao_rays;
    int open = 0;
    for (int k = 0; k < count; ++k) open += !occluded(tracer, ao_probe(base, rng));
    rays += uint64_t(count);
    return ao_radiance(open, count);
}

// The share of a sampled light's distance a shadow ray stops short of, so that it does not find the emitter it aims
// at (the sun's rays are unbounded).
constexpr float kShadowShortening = 1e-3f;

// A path's shadow ray, and what it adds to the path's radiance if it reaches its light.
struct ShadowRay {
    Ray ray;
    Vec3 contribution;
};

// The state of a `nee` path between bounces beyond PathState's.
struct NeeState {
    float bounce_pdf = 0.0f;  // the solid angle pdf of the bounce that made the current ray (none for the camera's)
};

// `nee`: one bounce of the diffuse path with next-event estimation. At every bounce that continues, one light sample
// through a shadow ray (any hit; returned in `shadow`, which is traced by the caller) and the cosine-weighted bounce,
// each weighed against the other's pdf by the power heuristic (Veach 1997, sec. 9.2); the white sky is found by
// bounces alone. Emitters count on either side, as under `diffuse`, so with the scene's emitters as lights both
// converge to the same image. Returns whether the path goes on, from `next`.
[[gnu::always_inline]] inline bool nee_bounce(const ShadingScene& scene, const Ray& ray, bool found, const SurfaceHit& surface,
                                              int depth, PathState& path, NeeState& nee, Rng& rng, Ray& next,
                                              std::optional<ShadowRay>& shadow) {
    constexpr float kInvPi = std::numbers::inv_pi_v<float>;
    const Lights& lights = *scene.lights;
    shadow.reset();
    if (!found) {
        float sun = 0.0f;
        if (lights.in_sun(ray.dir)) sun = Lights::sun_radiance() * (depth > 0 ? power_heuristic(nee.bounce_pdf, lights.sun_pdf()) : 1.0f);
        path.radiance += path.throughput * (1.0f + sun);
        return false;
    }
    const Vec3 n = facing_normal(ray, surface);
    if (scene.emitters) {
        const Vec3 le = scene.emission(surface.prim);
        if (le != Vec3(0.0f)) {
            const float d = glm::length(surface.point - ray.org);
            const float w = depth > 0 ? power_heuristic(nee.bounce_pdf, lights.emitter_pdf(le, d, -glm::dot(n, ray.dir))) : 1.0f;
            path.radiance += path.throughput * le * w;
        }
    }
    path.throughput *= scene.albedo(surface.prim);
    if (depth == scene.settings.max_bounces) return false;
    const LightSample light = lights.sample(surface.point, rng.next_float(), rng.next_float(), rng.next_float());
    const float cos_light = glm::dot(n, light.direction);
    if (light.pdf > 0.0f && cos_light > 0.0f) {
        const float bsdf_pdf = cos_light * kInvPi;
        shadow = ShadowRay{leaving_ray(surface, n, light.direction, light.distance * (1.0f - kShadowShortening)),
                           path.throughput * light.radiance * (bsdf_pdf / light.pdf * power_heuristic(light.pdf, bsdf_pdf))};
    }
    const Vec3 dir = cosine_direction(n, rng.next_float(), rng.next_float());
    next.org = offset_ray_origin(surface.point, n, surface.point_error);
    next.dir = dir;
    next.tmin = 0.0f;
    next.tmax = std::numeric_limits<float>::infinity();
    nee.bounce_pdf = glm::dot(n, dir) * kInvPi;
    return true;
}

template <class Tracer>
Vec3 trace_nee_path(const Tracer& tracer, const ShadingScene& scene, Ray& ray, Rng& rng, uint64_t& rays) {
    PathState path;
    NeeState nee;
    std::optional<ShadowRay> shadow;
    for (int depth = 0;; ++depth) {
        ++rays;
        SurfaceHit surface;
        const bool found = closest_surface(tracer, scene, ray, surface);
        const bool goes_on = nee_bounce(scene, ray, found, surface, depth, path, nee, rng, ray, shadow);
        if (shadow) {
            ++rays;
            if (!occluded(tracer, shadow->ray)) path.radiance += shadow->contribution;
        }
        if (!goes_on) break;
    }
    return path.radiance;
}

// Pixel (x, y)'s sample of frame `frame` in the frame's workload, added to `accumulated`.
template <class Tracer>
[[gnu::always_inline]] inline void trace_pixel(const Tracer& tracer, const ShadingScene& scene, const PinholeCamera& camera,
                                               uint32_t frame, int x, int y, Image& accumulated, uint64_t& rays) {
    Rng rng(uint64_t(y) * uint64_t(scene.settings.width) + uint64_t(x), frame);
    const float u = rng.next_float(), v = rng.next_float();
    Ray ray = camera.generate(x, y, u, v);  // built in place: trace_path takes it by reference
    switch (scene.settings.workload) {
    case Workload::Diffuse: accumulated.add(x, y, trace_path(tracer, scene, ray, rng, rays)); break;
    case Workload::Camera: accumulated.add(x, y, trace_camera(tracer, scene, ray, rays)); break;
    case Workload::Nee: accumulated.add(x, y, trace_nee_path(tracer, scene, ray, rng, rays)); break;
    case Workload::Ao: accumulated.add(x, y, trace_ao(tracer, scene, ray, rng, rays)); break;
    }
}

// A frame's sample (FrameSettings::sample_stride > 1): square tiles of kSampleTile pixels a side (neighbours' paths
// share nodes and cache lines as in a whole frame, which shorter runs of pixels did not reproduce: trees of more nodes
// looked slower than they trace), one tile in each `stride` tiles in raster order, at a scrambled place, so that the
// tiles cover the image evenly without following its columns.
constexpr int kSampleTile = 8;
inline uint64_t sample_tile(uint64_t k, uint32_t stride) { return k * stride + (k * 2654435761u) % stride; }

// The k-th tile render_frame traces: every kFrameTile tile in raster order, or the sample's k-th tile.
constexpr int kFrameTile = 16;
struct TileRect {
    int x0, y0, size;
};
inline TileRect traced_tile(int k, int w, uint32_t stride) {
    const int size = stride > 1 ? kSampleTile : kFrameTile, tiles_x = (w + size - 1) / size;
    const uint64_t tile = stride > 1 ? sample_tile(uint64_t(k), stride) : uint64_t(k);
    return {int(tile % uint64_t(tiles_x)) * size, int(tile / uint64_t(tiles_x)) * size, size};
}
// How many tiles render_frame traces with this stride: one in each run of `stride`, and one more where the last,
// partial run reaches its sampled tile.
inline int traced_tiles(int w, int h, uint32_t stride) {
    const int size = stride > 1 ? kSampleTile : kFrameTile;
    const uint64_t tiles = uint64_t((w + size - 1) / size) * uint64_t((h + size - 1) / size);
    if (stride <= 1) return int(tiles);
    return int(tiles / stride + (sample_tile(tiles / stride, stride) < tiles));
}
// The pixels render_frame traces with this stride.
inline uint64_t traced_pixels(int w, int h, uint32_t stride) {
    uint64_t pixels = 0;
    for (int k = 0; k < traced_tiles(w, h, stride); ++k) {
        const TileRect t = traced_tile(k, w, stride);
        pixels += uint64_t(std::min(t.x0 + t.size, w) - t.x0) * uint64_t(std::min(t.y0 + t.size, h) - t.y0);
    }
    return pixels;
}

// Renders one sample per pixel of frame `frame` (of the sample's pixels only, with settings.sample_stride > 1) and
// adds it to `accumulated`. Returns rays traced. `on_tile` (optional) is called after each tile with the fraction of
// the frame done.
template <class Tracer>
uint64_t render_frame(const Tracer& tracer, const ShadingScene& scene, const PinholeCamera& camera,
                      uint32_t frame, Image& accumulated, const std::function<void(float)>& on_tile = {}) {
    const int w = scene.settings.width, h = scene.settings.height;
    const uint32_t stride = scene.settings.sample_stride;
    const int tiles = traced_tiles(w, h, stride);
    std::vector<uint64_t> tile_rays(size_t(tiles), 0);
    std::atomic<int> done{0};
    tbb::parallel_for(0, tiles, [&](int tile) {
        uint64_t rays = 0;
        const TileRect t = traced_tile(tile, w, stride);
        for (int y = t.y0; y < std::min(t.y0 + t.size, h); ++y) {
            for (int x = t.x0; x < std::min(t.x0 + t.size, w); ++x) trace_pixel(tracer, scene, camera, frame, x, y, accumulated, rays);
        }
        tile_rays[size_t(tile)] = rays;
        if (on_tile) on_tile(float(done.fetch_add(1) + 1) / float(tiles));
    });
    uint64_t total = 0;
    for (uint64_t r : tile_rays) total += r;
    return total;
}

}  // namespace canopy
