#pragma once
// Numerical accuracy, measured: rays shot from inside closed spheres at their vertices and shared edges (where a
// non-watertight test leaks) and at random, as the sphere is scaled from 1e-6 to 1e6 and moved out to 1e7, for every
// intersector and traversal mode. Leaks per million rays, hit-distance error against an extended-precision oracle.
// On scene files, random rays: the hit-distance error of short hits, the kernel's t against precise_t's.
#include "base/geometry.h"
#include "kernels/ray.h"
#include "experiments/command.h"

#include <span>
#include <string>
#include <vector>

namespace canopy {

// An octahedron subdivided `levels` times and projected onto the sphere: 8 * 4^levels triangles, neighbours
// share exact vertices, so the mesh is closed at any scale.
std::vector<Triangle> closed_sphere(int levels, const Vec3& center, float radius);

// Rays from inside the sphere (within half its radius of the centre): one in three aimed exactly at a vertex, one
// in three at a point on a shared edge, the rest in random directions. Deterministic for a seed. Throws
// std::invalid_argument for a sphere too small for float to tell its points apart where it lies.
std::vector<Ray> rays_from_inside(std::span<const Triangle> sphere, const Vec3& center, float radius, size_t count,
                                  uint64_t seed);

struct AccuracyCase {
    double scale;   // sphere radius
    double offset;  // the centre is (offset, -offset, offset)
};

struct AccuracyRow {
    AccuracyCase where;
    std::string mode;        // kernel, e.g. "bvh8", "bvh8 fast mt"
    uint64_t rays = 0;
    uint64_t leaks = 0;      // rays from inside that found no hit
    double t_error_median = 0, t_error_max = 0;  // |t - t_exact| / t_exact over hits
    double precise_t_error_max = 0;  // the same for precise_t (kernels/precise_distance.h)
    double point_error_ulps = 0;  // max per-axis |o + t d - p_exact| in float spacings at the point's largest coordinate
    double ns_per_ray = 0;   // one query through the accelerator's trace() in parallel, call overhead included

    double leaks_per_million() const { return rays ? 1e6 * double(leaks) / double(rays) : 0.0; }
};

// Relative hit-distance errors |t - t_exact| / t_exact over a set of hits.
struct RelativeErrors {
    uint64_t hits = 0;
    double p99 = 0, p999 = 0, max = 0;
};

// A scene file's random rays (origins uniform in its box, directions uniform on the sphere: a distance query's rays)
// through one intersector, robust traversal.
struct SceneAccuracyRow {
    std::string scene;
    std::string mode;            // kernel, e.g. "bvh8", "bvh8 mt"
    uint64_t rays = 0, hits = 0;
    double short_limit = 0;      // 1% of the scene's diagonal
    RelativeErrors kernel, precise;              // every hit: the kernel's t, precise_t
    RelativeErrors short_kernel, short_precise;  // hits whose exact t is under short_limit
    double ns_per_ray = 0;       // as AccuracyRow's
    double precise_ns_per_hit = 0;  // precise_t over the hits in ray order, one thread
};

struct AccuracyOptions {
    std::string builder = "binned";
    std::string kernel = "auto";
    size_t rays = 200000;       // per case and mode
    int sphere_levels = 5;      // 8192 triangles
    std::vector<std::string> scenes;  // measured instead of the sphere sweep when given
    std::string json_path, plot_path;
};

// The scale sweep (centre at the origin, radius 1e-6 .. 1e6) and the offset sweep (radius 100, centre out to 1e7).
std::vector<AccuracyCase> accuracy_cases();

// Every case under every combination of watertight/Möller–Trumbore and robust/fast traversal.
std::vector<AccuracyRow> measure_accuracy(const AccuracyOptions& options, const std::vector<AccuracyCase>& cases);

// `options.rays` random rays through the scene under the watertight and the Möller–Trumbore intersector.
std::vector<SceneAccuracyRow> measure_scene_accuracy(const AccuracyOptions& options, const std::string& scene);

// Measures every case, or every scene when given; prints the table, writes JSON and the plot when asked.
void run_accuracy(const AccuracyOptions& options);
// `canopy accuracy`, its options and its run.
void register_accuracy(CLI::App& canopy);

}  // namespace canopy
