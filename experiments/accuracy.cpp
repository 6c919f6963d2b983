#include "experiments/accuracy.h"
#include "base/output_path.h"

#include "engine/options.h"
#include "engine/random_ray_sample.h"
#include "experiments/command.h"
#include "experiments/plot.h"
#include "kernels/precise_distance.h"
#include "renderer/distributed.h"
#include "renderer/frames.h"

#include <CLI/CLI.hpp>
#include <glm/vec3.hpp>
#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <numbers>
#include <random>
#include <stdexcept>

namespace canopy {

std::vector<Triangle> closed_sphere(int levels, const Vec3& center, float radius) {
    const Vec3 px(1, 0, 0), nx(-1, 0, 0), py(0, 1, 0), ny(0, -1, 0), pz(0, 0, 1), nz(0, 0, -1);
    std::vector<Triangle> tris = {{px, py, pz}, {py, nx, pz}, {nx, ny, pz}, {ny, px, pz},
                                  {py, px, nz}, {nx, py, nz}, {ny, nx, nz}, {px, ny, nz}};
    for (int l = 0; l < levels; ++l) {
        std::vector<Triangle> finer;
        for (const Triangle& t : tris) {
            // Each midpoint is computed from the same two vertices by both triangles sharing the edge.
            const Vec3 a = glm::normalize(t.v0 + t.v1), b = glm::normalize(t.v1 + t.v2), c = glm::normalize(t.v2 + t.v0);
            finer.insert(finer.end(), {{t.v0, a, c}, {a, t.v1, b}, {c, b, t.v2}, {a, b, c}});
        }
        tris.swap(finer);
    }
    for (Triangle& t : tris) t = {center + radius * t.v0, center + radius * t.v1, center + radius * t.v2};
    return tris;
}

std::vector<Ray> rays_from_inside(std::span<const Triangle> sphere, const Vec3& center, float radius, size_t count,
                                  uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f), unit(0.0f, 1.0f);
    std::uniform_int_distribution<size_t> pick(0, sphere.size() - 1);
    std::vector<Ray> rays;
    rays.reserve(count);
    constexpr size_t kMostDegenerate = 1000;
    size_t degenerate = 0;
    while (rays.size() < count) {
        const Vec3 origin = center + 0.5f * radius * Vec3(u(rng), u(rng), u(rng)) / std::sqrt(3.0f);
        const Triangle& t = sphere[pick(rng)];
        Vec3 d;
        switch (rays.size() % 3) {
            case 0: d = t.v0 - origin; break;
            case 1: d = glm::mix(t.v0, t.v1, unit(rng)) - origin; break;
            default: d = Vec3(u(rng), u(rng), u(rng)); break;  // a direction, not a point: far out, a point within 1
                                                                 // of the origin rounds onto it
        }
        // An origin that rounds onto its vertex (a sphere smaller than the float spacing where it lies) is drawn again.
        if (glm::dot(d, d) > 0.0f) rays.push_back({origin, glm::normalize(d)});
        else if (++degenerate > kMostDegenerate)
            throw std::invalid_argument("accuracy: a sphere of radius " + std::to_string(radius) +
                                        " is below float's spacing at its centre: no ray from inside it has a direction");
    }
    return rays;
}

std::vector<AccuracyCase> accuracy_cases() {
    std::vector<AccuracyCase> cases;
    for (double scale : {1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6}) cases.push_back({scale, 0.0});
    for (double offset : {1e1, 1e3, 1e5, 1e7}) cases.push_back({100.0, offset});
    return cases;
}

namespace {

// The exact distance along the float ray to the plane of the triangle it hit, in long double (64-bit significands,
// 11 bits more than precise_t's double): the oracle of the kernel's t and of precise_t's.
double exact_distance(const Ray& ray, const Triangle& t) {
    using LongVec3 = glm::vec<3, long double>;
    const LongVec3 v0(t.v0), e1 = LongVec3(t.v1) - v0, e2 = LongVec3(t.v2) - v0;
    const LongVec3 n = glm::cross(e1, e2);
    return double(glm::dot(n, v0 - LongVec3(ray.org)) / glm::dot(n, LongVec3(ray.dir)));
}

// A hit's exact distance and the relative errors of the kernel's t and of precise_t's rounded to float, the
// distance a caller of precise_t reports.
struct HitDistance {
    double exact, kernel_error, precise_error;
};

HitDistance hit_distance(const Ray& ray, const Hit& hit, const Triangle& t, double precise) {
    const double exact = exact_distance(ray, t);
    const auto relative_error = [exact](float distance) { return std::abs(double(distance) - exact) / exact; };
    return {exact, relative_error(hit.t), relative_error(float(precise))};
}

RelativeErrors relative_errors(std::vector<double> errors) {
    RelativeErrors r{errors.size()};
    if (errors.empty()) return r;
    std::sort(errors.begin(), errors.end());
    const auto quantile = [&](double q) { return errors[std::min(errors.size() - 1, size_t(q * double(errors.size())))]; };
    r.p99 = quantile(0.99), r.p999 = quantile(0.999), r.max = errors.back();
    return r;
}

// The spacing of floats at the largest coordinate of p: the error a float point cannot avoid.
double ulp_at(const glm::dvec3& p) {
    const float m = float(std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}));
    return double(std::nextafter(m, INFINITY)) - double(m);
}

double max_abs_difference(const Vec3& p, const glm::dvec3& q) {
    return std::max({std::abs(double(p.x) - q.x), std::abs(double(p.y) - q.y), std::abs(double(p.z) - q.z)});
}

struct Mode {
    bool robust, watertight;
};

struct TracedRays {
    std::string kernel;
    std::vector<Hit> hits;
    double ns_per_ray = 0;
};

// Every ray's closest hit through a tree of `flat` in one intersector and traversal mode, in parallel.
TracedRays trace_all(const AccuracyOptions& o, const Mode& mode, const FlatScene& flat, const std::vector<Ray>& rays) {
    const auto accel = make_canopy_accelerator(flat, {o.builder, "", o.kernel, mode.robust, mode.watertight});
    accel->prepare();
    accel->build();
    TracedRays traced{accel->kernel(), std::vector<Hit>(rays.size())};
    const auto start = std::chrono::steady_clock::now();
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) { traced.hits[i] = accel->trace(rays[i]); });
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count();
    traced.ns_per_ray = ns / double(rays.size());
    return traced;
}

AccuracyRow measure_case(const AccuracyOptions& o, const AccuracyCase& c, const Mode& mode,
                         const std::vector<Triangle>& sphere, const std::vector<Ray>& rays, const FlatScene& flat) {
    const TracedRays traced = trace_all(o, mode, flat, rays);
    AccuracyRow row{c, traced.kernel, rays.size()};
    row.ns_per_ray = traced.ns_per_ray;
    std::vector<double> t_errors;
    t_errors.reserve(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit& hit = traced.hits[i];
        if (!hit.found()) {
            ++row.leaks;
            continue;
        }
        const HitDistance distance = hit_distance(rays[i], hit, sphere[hit.prim], precise_t(sphere[hit.prim], rays[i]));
        t_errors.push_back(distance.kernel_error);
        row.precise_t_error_max = std::max(row.precise_t_error_max, distance.precise_error);
        const Vec3 p = rays[i].org + hit.t * rays[i].dir;  // as the renderer computes it
        const glm::dvec3 p_exact = glm::dvec3(rays[i].org) + distance.exact * glm::dvec3(rays[i].dir);
        row.point_error_ulps = std::max(row.point_error_ulps, max_abs_difference(p, p_exact) / ulp_at(p_exact));
    }
    if (!t_errors.empty()) {
        std::nth_element(t_errors.begin(), t_errors.begin() + t_errors.size() / 2, t_errors.end());
        row.t_error_median = t_errors[t_errors.size() / 2];
        row.t_error_max = *std::max_element(t_errors.begin(), t_errors.end());
    }
    return row;
}

struct PreciseDistances {
    std::vector<double> t;  // a ray's precise_t, NaN for a miss
    double ns_per_hit = 0;
};

// precise_t of every hit, in ray order on one thread, its time the fastest of kRounds passes (single passes on a
// shared machine varied widely, docs/results.md#precise-distances-for-short-hits): its cost where the API would call
// it, the hit triangle's corners fetched from the scene's array.
PreciseDistances precise_distances(const std::vector<Ray>& rays, const std::vector<Hit>& hits,
                                   const std::vector<Triangle>& tris) {
    constexpr int kRounds = 5;
    PreciseDistances precise{std::vector<double>(rays.size(), std::numeric_limits<double>::quiet_NaN())};
    const size_t count = size_t(std::count_if(hits.begin(), hits.end(), [](const Hit& hit) { return hit.found(); }));
    double fastest = std::numeric_limits<double>::infinity();
    for (int round = 0; round < kRounds; ++round) {
        const auto start = std::chrono::steady_clock::now();
        for (size_t i = 0; i < rays.size(); ++i)
            if (hits[i].found()) precise.t[i] = precise_t(tris[hits[i].prim], rays[i]);
        fastest = std::min(fastest, std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count());
    }
    precise.ns_per_hit = count ? fastest / double(count) : 0.0;
    return precise;
}

SceneAccuracyRow measure_scene_mode(const AccuracyOptions& o, const std::string& scene, const Mode& mode,
                                    const FlatScene& flat, const std::vector<Ray>& rays) {
    const TracedRays traced = trace_all(o, mode, flat, rays);
    SceneAccuracyRow row{scene, traced.kernel, rays.size()};
    row.short_limit = 0.01 * double(glm::length(flat.bounds.extent()));
    row.ns_per_ray = traced.ns_per_ray;
    const PreciseDistances precise_ts = precise_distances(rays, traced.hits, flat.triangles);
    row.precise_ns_per_hit = precise_ts.ns_per_hit;
    std::vector<double> kernel, precise, short_kernel, short_precise;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit& hit = traced.hits[i];
        if (!hit.found()) continue;
        const HitDistance distance = hit_distance(rays[i], hit, flat.triangles[hit.prim], precise_ts.t[i]);
        kernel.push_back(distance.kernel_error), precise.push_back(distance.precise_error);
        if (distance.exact < row.short_limit)
            short_kernel.push_back(distance.kernel_error), short_precise.push_back(distance.precise_error);
    }
    row.hits = kernel.size();
    row.kernel = relative_errors(std::move(kernel)), row.precise = relative_errors(std::move(precise));
    row.short_kernel = relative_errors(std::move(short_kernel)), row.short_precise = relative_errors(std::move(short_precise));
    return row;
}

void print_table(const std::vector<AccuracyRow>& rows) {
    std::printf("\n%10s %10s %-16s %10s %9s %12s %12s %12s %12s %9s\n", "radius", "offset", "kernel", "rays", "leaks/M",
                "t err med", "t err max", "precise max", "point ulps", "ns/ray");
    for (const AccuracyRow& r : rows)
        std::printf("%10.0e %10.0e %-16s %10llu %9.1f %12.2e %12.2e %12.2e %12.2f %9.1f\n", r.where.scale, r.where.offset,
                    r.mode.c_str(), (unsigned long long)r.rays, r.leaks_per_million(), r.t_error_median, r.t_error_max,
                    r.precise_t_error_max, r.point_error_ulps, r.ns_per_ray);
    std::printf("t err: |t - t_exact| / t_exact against long double on the hit triangle; precise: precise_t's "
                "(kernels/precise_distance.h), rounded to float; point ulps: max |o + t d - p_exact| per axis in floats spaced at the point's largest coordinate\n");
}

void print_scene_table(const std::vector<SceneAccuracyRow>& rows) {
    std::printf("\n%-16s %-10s %9s %9s %10s %11s %11s %11s %13s %13s %13s %11s %13s %9s %10s\n", "scene", "kernel",
                "rays", "hits", "short hits", "t p99", "t p99.9", "t max", "precise p99", "precise p99.9", "precise max",
                "all t p99.9", "all precise", "ns/ray", "precise ns");
    for (const SceneAccuracyRow& r : rows)
        std::printf("%-16s %-10s %9llu %9llu %10llu %11.2e %11.2e %11.2e %13.2e %13.2e %13.2e %11.2e %13.2e %9.1f %10.1f\n",
                    r.scene.c_str(), r.mode.c_str(), (unsigned long long)r.rays, (unsigned long long)r.hits,
                    (unsigned long long)r.short_kernel.hits, r.short_kernel.p99, r.short_kernel.p999, r.short_kernel.max,
                    r.short_precise.p99, r.short_precise.p999, r.short_precise.max, r.kernel.p999, r.precise.p999,
                    r.ns_per_ray, r.precise_ns_per_hit);
    std::printf("random rays (origins uniform in the scene's box, directions uniform); |t - t_exact| / t_exact against "
                "long double on the hit triangle over short hits (exact t under 1%% of the scene's diagonal): the "
                "kernel's t, and precise_t's (kernels/precise_distance.h) rounded to float; all: p99.9 over every hit; "
                "precise ns: a call, one thread\n");
}

nlohmann::json to_json(const RelativeErrors& e) {
    return {{"hits", e.hits}, {"p99", e.p99}, {"p999", e.p999}, {"max", e.max}};
}

void write_json(const nlohmann::json& out, const std::string& path) {
    std::ofstream file(path);
    file << out.dump(2) << "\n";
    if (!file) throw std::runtime_error(path + ": cannot write accuracy JSON");
}

nlohmann::json rows_json(const std::vector<AccuracyRow>& rows) {
    nlohmann::json out = nlohmann::json::array();
    for (const AccuracyRow& r : rows)
        out.push_back({{"radius", r.where.scale}, {"offset", r.where.offset}, {"kernel", r.mode}, {"rays", r.rays},
                       {"leaks", r.leaks}, {"leaks_per_million", r.leaks_per_million()},
                       {"t_error_median", r.t_error_median}, {"t_error_max", r.t_error_max},
                       {"precise_t_error_max", r.precise_t_error_max}, {"point_error_ulps", r.point_error_ulps},
                       {"ns_per_ray", r.ns_per_ray}});
    return out;
}

nlohmann::json rows_json(const std::vector<SceneAccuracyRow>& rows) {
    nlohmann::json out = nlohmann::json::array();
    for (const SceneAccuracyRow& r : rows)
        out.push_back({{"scene", r.scene}, {"kernel", r.mode}, {"rays", r.rays}, {"hits", r.hits},
                       {"short_limit", r.short_limit}, {"t_error", to_json(r.kernel)},
                       {"precise_t_error", to_json(r.precise)}, {"short_t_error", to_json(r.short_kernel)},
                       {"short_precise_t_error", to_json(r.short_precise)}, {"ns_per_ray", r.ns_per_ray},
                       {"precise_ns_per_hit", r.precise_ns_per_hit}});
    return out;
}

// Maximum relative distance error against the largest coordinate of the scene, a curve per intersector and
// sweep (the traversal mode does not change a hit's distance, only whether it is found).
void write_plot(const std::vector<AccuracyRow>& rows, const std::string& path) {
    LogLogPlot plot{"hit distance error against coordinate magnitude", "largest |coordinate| of the scene",
                    "max |t - t_exact| / t_exact", {}};
    for (const char* intersector : {"watertight", "mt"}) {
        for (const bool offset_sweep : {false, true}) {
            PlotSeries series{std::string(intersector == std::string("mt") ? "Moller-Trumbore" : "watertight") +
                              (offset_sweep ? ", moved" : ", scaled"), {}};
            for (const AccuracyRow& r : rows) {
                const bool mt = r.mode.find(" mt") != std::string::npos;
                if (mt != (intersector == std::string("mt")) || (r.where.offset > 0) != offset_sweep) continue;
                if (r.mode.find("fast") != std::string::npos) continue;  // the same distances as robust
                series.points.push_back({r.where.offset + r.where.scale, std::max(r.t_error_max, 1e-12)});
            }
            plot.series.push_back(std::move(series));
        }
    }
    write_plot_png(plot, path);
}

}  // namespace

std::vector<AccuracyRow> measure_accuracy(const AccuracyOptions& o, const std::vector<AccuracyCase>& cases) {
    std::vector<AccuracyRow> rows;
    for (const AccuracyCase& c : cases) {
        const Vec3 center = float(c.offset) * Vec3(1, -1, 1);
        FlatScene flat;
        flat.triangles = closed_sphere(o.sphere_levels, center, float(c.scale));
        for (const Triangle& t : flat.triangles) flat.bounds.extend(BBox::of(t));
        const std::vector<Ray> rays = rays_from_inside(flat.triangles, center, float(c.scale), o.rays, 1234);
        for (const Mode mode : {Mode{true, true}, Mode{false, true}, Mode{true, false}, Mode{false, false}})
            rows.push_back(measure_case(o, c, mode, flat.triangles, rays, flat));
    }
    return rows;
}

std::vector<SceneAccuracyRow> measure_scene_accuracy(const AccuracyOptions& o, const std::string& scene) {
    const Scene loaded = load_scene(scene);
    const FlatScene flat = flatten(loaded);
    const std::vector<Ray> rays = random_rays(flat.bounds, o.rays, 1234);
    std::vector<SceneAccuracyRow> rows;
    for (const Mode mode : {Mode{true, true}, Mode{true, false}})
        rows.push_back(measure_scene_mode(o, loaded.name, mode, flat, rays));
    return rows;
}

void run_accuracy(const AccuracyOptions& o) {
    if (!o.scenes.empty()) {
        std::vector<SceneAccuracyRow> rows;
        for (const std::string& scene : o.scenes) {
            const std::vector<SceneAccuracyRow> more = measure_scene_accuracy(o, scene);
            rows.insert(rows.end(), more.begin(), more.end());
        }
        print_scene_table(rows);
        if (!o.json_path.empty()) write_json(rows_json(rows), o.json_path), std::printf("wrote %s\n", o.json_path.c_str());
        return;
    }
    const std::vector<AccuracyRow> rows = measure_accuracy(o, accuracy_cases());
    print_table(rows);
    if (!o.json_path.empty()) write_json(rows_json(rows), o.json_path), std::printf("wrote %s\n", o.json_path.c_str());
    if (!o.plot_path.empty()) write_plot(rows, o.plot_path), std::printf("wrote %s\n", o.plot_path.c_str());
}

void register_accuracy(CLI::App& canopy) {
    struct Parsed {
        AccuracyOptions options;
        int threads = 0;
    };
    auto p = std::make_shared<Parsed>();
    AccuracyOptions& ac = p->options;
    CLI::App* accuracy = canopy.add_subcommand("accuracy", "Leaks and hit-distance error of every intersector and traversal mode, scaled and moved");
    accuracy->add_option("--builder", ac.builder, "Builder (of a BVH, or kdtree: a kd-tree): " + builder_names(false))
        ->check([](const std::string& builder) {
            return builder == "auto" ? std::string("auto times its candidates on frames; accuracy traces no frames: name a builder")
                                     : std::string();
        })
        ->capture_default_str();
    accuracy->add_option("--kernel", ac.kernel, "Kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    accuracy->add_option("--rays", ac.rays, "Rays per case (or scene) and mode")->check(CLI::Range(1, 100000000))->capture_default_str();
    CLI::Option* scenes = accuracy->add_option("scene", ac.scenes,
        "Scenes (scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S): random rays through each, the short hits' "
        "distance errors, instead of the sphere sweep");
    accuracy->add_option("--json", ac.json_path, "Write the rows as JSON");
    accuracy->add_option("--plot", ac.plot_path, "Write a PNG: distance error against coordinate magnitude (the sphere sweep)")
        ->excludes(scenes);
    accuracy->add_option("--threads", p->threads, "Threads (0: all)")->check(CLI::Range(0, 4096));
    accuracy->callback([p] {
        if (!distributed::is_root()) return;  // not split: under a job, rank 0's alone
        if (!p->options.json_path.empty()) check_output_path("--json", p->options.json_path);
        if (!p->options.plot_path.empty()) check_output_path("--plot", p->options.plot_path, {".png"});
        const auto limit = limit_threads(p->threads);
        run_accuracy(p->options);
    });
}

}  // namespace canopy
