#pragma once
// Numerical accuracy, measured: rays shot from inside closed spheres at their vertices and shared edges (where a
// non-watertight test leaks) and at random, as the sphere is scaled from 1e-6 to 1e6 and moved out to 1e7, for every
// intersector and traversal mode. Leaks per million rays, hit-distance error against a double-precision oracle.
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
    double point_error_ulps = 0;  // max per-axis |o + t d - p_exact| in float spacings at the point's largest coordinate
    double ns_per_ray = 0;   // one query through the accelerator's trace() in parallel, call overhead included

    double leaks_per_million() const { return rays ? 1e6 * double(leaks) / double(rays) : 0.0; }
};

struct AccuracyOptions {
    std::string builder = "binned";
    std::string kernel = "auto";
    size_t rays = 200000;       // per case and mode
    int sphere_levels = 5;      // 8192 triangles
    std::string json_path, plot_path;
};

// The scale sweep (centre at the origin, radius 1e-6 .. 1e6) and the offset sweep (radius 100, centre out to 1e7).
std::vector<AccuracyCase> accuracy_cases();

// Every case under every combination of watertight/Möller–Trumbore and robust/fast traversal.
std::vector<AccuracyRow> measure_accuracy(const AccuracyOptions& options, const std::vector<AccuracyCase>& cases);

// Measures every case, prints the table, writes JSON and the plot when asked.
void run_accuracy(const AccuracyOptions& options);
// `canopy accuracy`, its options and its run.
void register_accuracy(CLI::App& canopy);

}  // namespace canopy
