#include "renderer/auto_builder.h"

#include "accel/builder.h"
#include "accel/parallel.h"

#include <algorithm>
#include <cstdio>
#include <limits>

namespace canopy {

// Box excess over each mesh's own triangles, not the flattened copies: an instanced scene pays for its unique
// geometry only (zoo-1024's 50 M instanced triangles are 148 k unique ones).
SceneStatistics scene_statistics(const Scene& scene, const FlatScene& flat) {
    SceneStatistics s;
    s.triangles = flat.triangles.size();
    for (const Instance& instance : scene.instances)
        for (const Object& object : scene.meshes[instance.mesh].objects) s.placements += object.triangle_count > 0;
    using Sums = std::pair<double, double>;  // box half areas, twice the triangle areas
    Sums sums{0.0, 0.0};
    BBox bounds;  // of the meshes, each in its own space: the world for a scene of identity placements
    for (const Mesh& mesh : scene.meshes) {
        for (const Vec3& p : mesh.positions) bounds.extend(p);
        s.unique_triangles += mesh.triangles.size();
        const Sums mesh_sums = parallel::reduce(
            mesh.triangles.size(), 16 * 1024, Sums{0.0, 0.0},
            [&](size_t begin, size_t end) {
                Sums partial{0.0, 0.0};
                for (size_t i = begin; i < end; ++i) {
                    const glm::uvec3& f = mesh.triangles[i];
                    const Triangle t{mesh.positions[f.x], mesh.positions[f.y], mesh.positions[f.z]};
                    partial.first += BBox::of(t).half_area();
                    partial.second += 2.0 * triangle_area(t);
                }
                return partial;
            },
            [](const Sums& a, const Sums& b) { return Sums{a.first + b.first, a.second + b.second}; });
        sums = {sums.first + mesh_sums.first, sums.second + mesh_sums.second};
    }
    s.box_excess = sums.second > 0.0 ? sums.first / sums.second : 1.0;
    const double area = bounds.empty() ? 0.0 : double(bounds.half_area());
    s.reducible_cover = area > 0.0 ? std::max(0.0, sums.first - sums.second) / area : 0.0;
    const Vec3 eye = scene_camera(scene, flat).eye;
    s.camera_inside = glm::all(glm::greaterThan(eye, flat.bounds.lower)) && glm::all(glm::lessThan(eye, flat.bounds.upper));
    return s;
}

namespace {

// A candidate's cost model, from one `canopy bench` per scene on the project machine, 2 threads, bvh8 (README,
// "Choosing a builder"): build time per triangle built, and frame time relative to binned SAH's as a function of
// the scene's statistics.
struct Candidate {
    const char* builder;
    const char* toplevel;
    double build_ns_per_triangle;         // on scenes without slivers
    double sliver_build_ns_per_triangle;  // where splitting builders split (gen:cylinders)
    double (*relative_frame)(const SceneStatistics&);
};

// Scenes whose triangle boxes are this much larger than the triangles are made of long diagonal slivers
// (gen:cylinders measures 23.3; every shared scene and gen:surface 1.1 to 2.2): spatial splits pay there only.
constexpr double kSliverExcess = 5.0;
bool slivers(const SceneStatistics& s) { return s.box_excess > kSliverExcess; }
// Scanned and finely tessellated surfaces (bunny 1.90, dragon, armadillo, gen:surface 2.05) have randomly
// oriented triangles of similar size; architecture (crytek-sponza 1.48, sibenik 1.61, conference 1.59,
// gen:box 1.12, cornell-box 1.10) has large axis-aligned walls next to small detail.
constexpr double kScanExcess = 1.75;
bool architecture(const SceneStatistics& s) { return s.box_excess < kScanExcess; }
// Architecture whose triangle boxes a ray pierces far more often than their triangles: crytek-sponza 6.8 (big
// overlapping wall and arch triangles); sibenik 3.6, conference 3.7, gen:box 0.6, cornell-box 0.4, scans 1.7 to
// 2.9. Splitting pays there even without slivers. The threshold lies between the shared scenes that split well and
// those that do not; crytek-sponza is the only non-sliver scene measured above it.
constexpr double kSplitCover = 5.0;
bool dense_boxes(const SceneStatistics& s) { return architecture(s) && s.reducible_cover > kSplitCover; }

double same_as_binned(const SceneStatistics&) { return 1.0; }
// Against binned (bvh8): crytek-sponza 0.84, sibenik 1.00, conference 1.09, gen:box 1.12; scans 1.00 to 1.05;
// cylinders 0.38.
double bonsai_split_frame(const SceneStatistics& s) {
    return slivers(s) ? 0.38 : dense_boxes(s) ? 0.84 : architecture(s) ? 1.0 : 1.03;
}
// The same tree as binned without slivers (no triangle is split); cylinders 0.37.
double esc_frame(const SceneStatistics& s) { return slivers(s) ? 0.37 : 1.0; }
// crytek-sponza 0.75, sibenik 0.96, conference 0.92, gen:box 0.91; scans 1.01 to 1.04; not measured on
// slivers, where it cannot split.
double bittner_frame(const SceneStatistics& s) { return dense_boxes(s) ? 0.75 : architecture(s) ? 0.9 : 1.04; }
// One-triangle leaves, merged into blocks in the wide layout: architecture 1.18 to 1.38, scans 1.10 to 1.21,
// cylinders 1.86. The cheapest build, so it wins where a frame is cheap against building.
double lbvh_frame(const SceneStatistics& s) { return slivers(s) ? 1.86 : architecture(s) ? 1.25 : 1.15; }

// zoo-64, traversal against flat's: rebraid 1.035. Plain two-level (1.07) builds in the same time and traces
// slower, so it is no candidate.
double rebraid_frame(const SceneStatistics&) { return 1.035; }

constexpr Candidate kCandidates[] = {
    {"binned", "flat", 190.0, 240.0, &same_as_binned},
    {"bonsai-split", "flat", 280.0, 1130.0, &bonsai_split_frame},
    {"esc", "flat", 190.0, 1040.0, &esc_frame},
    {"bittner", "flat", 4000.0, 4000.0, &bittner_frame},
    {"lbvh", "flat", 90.0, 100.0, &lbvh_frame},
    // Instanced objects: each unique triangle is built once (zoo-64: 25 ms against flat binned's 820 ms).
    {"binned", "rebraid", 600.0, 600.0, &rebraid_frame},
};
// Frame time per pixel with binned, 2 threads, bvh8: rooms seen from inside 1.4 to 2.6 us (crytek-sponza, sibenik,
// conference), objects seen from outside 0.07 to 0.6 us (geometric mean 0.2: the scans, cornell-box, gen:box,
// gen:surface, zoo-64), the sliver field 6.3 us.
constexpr double kInsideNsPerPixel = 2000.0, kOutsideNsPerPixel = 200.0, kSliverNsPerPixel = 6300.0;
double frame_ns_per_pixel(const SceneStatistics& s) {
    return slivers(s) ? kSliverNsPerPixel : s.camera_inside ? kInsideNsPerPixel : kOutsideNsPerPixel;
}
constexpr uint64_t kMaxFlattenedTriangles = 16'000'000;

}  // namespace

AutoChoice choose_builder(const SceneStatistics& stats, int frames, uint64_t pixels) {
    const bool instanced = stats.triangles > stats.unique_triangles;
    AutoChoice best;
    double best_ms = std::numeric_limits<double>::infinity(), frame_ms = 0.0, build_ms = 0.0;
    for (const Candidate& c : kCandidates) {
        const bool two_level = std::string(c.toplevel) != "flat";
        if (two_level && !instanced) continue;  // two-level only with instances
        // Flattening copies every instance: past this many triangles (about 2 GB of flat layout) two-level only.
        if (!two_level && instanced && stats.triangles > kMaxFlattenedTriangles) continue;
        const double built = double(two_level ? stats.unique_triangles : stats.triangles);
        const double build = built * (slivers(stats) ? c.sliver_build_ns_per_triangle : c.build_ns_per_triangle) * 1e-6;
        const double frame = double(pixels) * frame_ns_per_pixel(stats) * 1e-6 * c.relative_frame(stats);
        const double total = build + double(frames) * frame;
        if (total < best_ms) best_ms = total, best = {c.builder, c.toplevel, ""}, frame_ms = frame, build_ms = build;
    }
    char reason[320];
    std::snprintf(reason, sizeof reason,
                  "%llu triangles (%llu unique) in %llu placed objects, box excess %.2f, reducible cover %.1f, camera %s, "
                  "%d frames planned: predicted build %.1f ms + %d x %.1f ms",
                  (unsigned long long)stats.triangles, (unsigned long long)stats.unique_triangles,
                  (unsigned long long)stats.placements, stats.box_excess, stats.reducible_cover,
                  stats.camera_inside ? "inside" : "outside",
                  frames, build_ms, frames, frame_ms);
    best.reason = reason;
    return best;
}

}  // namespace canopy
