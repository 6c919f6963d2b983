#include "experiments/accuracy.h"
#include "base/output_path.h"

#include "engine/options.h"
#include "experiments/command.h"
#include "experiments/plot.h"
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

// The exact distance along the float ray to the plane of the triangle it hit, in double.
double exact_distance(const Ray& ray, const Triangle& t) {
    const glm::dvec3 v0(t.v0), e1 = glm::dvec3(t.v1) - v0, e2 = glm::dvec3(t.v2) - v0;
    const glm::dvec3 n = glm::cross(e1, e2);
    return glm::dot(n, v0 - glm::dvec3(ray.org)) / glm::dot(n, glm::dvec3(ray.dir));
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

AccuracyRow measure_case(const AccuracyOptions& o, const AccuracyCase& c, const Mode& mode,
                         const std::vector<Triangle>& sphere, const std::vector<Ray>& rays, const FlatScene& flat) {
    const auto accel = make_canopy_accelerator(flat, {o.builder, "", o.kernel, mode.robust, mode.watertight});
    accel->prepare();
    accel->build();
    std::vector<Hit> hits(rays.size());
    const auto start = std::chrono::steady_clock::now();
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) { hits[i] = accel->trace(rays[i]); });
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count();

    AccuracyRow row{c, accel->kernel(), rays.size()};
    row.ns_per_ray = ns / double(rays.size());
    std::vector<double> t_errors;
    t_errors.reserve(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) {
        if (!hits[i].found()) {
            ++row.leaks;
            continue;
        }
        const double exact = exact_distance(rays[i], sphere[hits[i].prim]);
        t_errors.push_back(std::abs(double(hits[i].t) - exact) / exact);
        const Vec3 p = rays[i].org + hits[i].t * rays[i].dir;  // as the renderer computes it
        const glm::dvec3 p_exact = glm::dvec3(rays[i].org) + exact * glm::dvec3(rays[i].dir);
        row.point_error_ulps = std::max(row.point_error_ulps, max_abs_difference(p, p_exact) / ulp_at(p_exact));
    }
    if (!t_errors.empty()) {
        std::nth_element(t_errors.begin(), t_errors.begin() + t_errors.size() / 2, t_errors.end());
        row.t_error_median = t_errors[t_errors.size() / 2];
        row.t_error_max = *std::max_element(t_errors.begin(), t_errors.end());
    }
    return row;
}

void print_table(const std::vector<AccuracyRow>& rows) {
    std::printf("\n%10s %10s %-16s %10s %9s %12s %12s %12s %9s\n", "radius", "offset", "kernel", "rays", "leaks/M",
                "t err med", "t err max", "point ulps", "ns/ray");
    for (const AccuracyRow& r : rows)
        std::printf("%10.0e %10.0e %-16s %10llu %9.1f %12.2e %12.2e %12.2f %9.1f\n", r.where.scale, r.where.offset,
                    r.mode.c_str(), (unsigned long long)r.rays, r.leaks_per_million(), r.t_error_median, r.t_error_max,
                    r.point_error_ulps, r.ns_per_ray);
    std::printf("t err: |t - t_exact| / t_exact against double precision; point ulps: max |o + t d - p_exact| per axis in floats spaced at the point's largest coordinate\n");
}

void write_json(const std::vector<AccuracyRow>& rows, const std::string& path) {
    nlohmann::json out = nlohmann::json::array();
    for (const AccuracyRow& r : rows)
        out.push_back({{"radius", r.where.scale}, {"offset", r.where.offset}, {"kernel", r.mode}, {"rays", r.rays},
                       {"leaks", r.leaks}, {"leaks_per_million", r.leaks_per_million()},
                       {"t_error_median", r.t_error_median}, {"t_error_max", r.t_error_max},
                       {"point_error_ulps", r.point_error_ulps}, {"ns_per_ray", r.ns_per_ray}});
    std::ofstream file(path);
    file << out.dump(2) << "\n";
    if (!file) throw std::runtime_error(path + ": cannot write accuracy JSON");
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

void run_accuracy(const AccuracyOptions& o) {
    const std::vector<AccuracyRow> rows = measure_accuracy(o, accuracy_cases());
    print_table(rows);
    if (!o.json_path.empty()) write_json(rows, o.json_path), std::printf("wrote %s\n", o.json_path.c_str());
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
    accuracy->add_option("--rays", ac.rays, "Rays per case and mode")->check(CLI::Range(1, 100000000))->capture_default_str();
    accuracy->add_option("--json", ac.json_path, "Write the rows as JSON");
    accuracy->add_option("--plot", ac.plot_path, "Write a PNG: distance error against coordinate magnitude");
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
