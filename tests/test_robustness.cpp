// Watertightness, extreme coordinates and scales, special directions and degenerate geometry.
#include "oracle.h"
#include "experiments/accuracy.h"
#include "test_scale.h"

#include <cmath>

using namespace canopy;
using namespace canopy::test;

namespace {

// A plane z = 0 of n x n unit squares, each split into two triangles along alternating diagonals.
std::vector<Triangle> tessellated_plane(int n, float scale, const Vec3& offset) {
    std::vector<Triangle> tris;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const Vec3 a = offset + scale * Vec3(i, j, 0), b = offset + scale * Vec3(i + 1, j, 0);
            const Vec3 c = offset + scale * Vec3(i + 1, j + 1, 0), d = offset + scale * Vec3(i, j + 1, 0);
            if ((i + j) % 2) tris.insert(tris.end(), {{a, b, c}, {a, c, d}});
            else tris.insert(tris.end(), {{a, b, d}, {b, c, d}});
        }
    return tris;
}

std::vector<Triangle> transformed(std::vector<Triangle> tris, float scale, const Vec3& offset) {
    for (Triangle& t : tris) t = {t.v0 * scale + offset, t.v1 * scale + offset, t.v2 * scale + offset};
    return tris;
}

// Counts rays that every kernel of every builder lets through although they must hit.
size_t count_leaks(std::span<const Triangle> tris, const std::vector<Ray>& rays) {
    size_t leaks = 0;
    for (const BuilderEntry& builder : builders()) {
        const BuiltScene built = build_with(builder.name, tris);
        for (const KernelUnderTest& kernel : kernels_of(built))
            for (const Ray& ray : rays) leaks += !kernel.closest(ray).found() + !kernel.any(ray);
    }
    return leaks;
}

// Rays from the library's generator plus the six axis directions (two with a negative zero) exactly through
// the octahedron's vertices.
std::vector<Ray> rays_from_center(std::span<const Triangle> sphere, const Vec3& center, float radius, size_t count) {
    std::vector<Ray> rays;
    for (const Vec3& d : {Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1), Vec3(0, 0, -1),
                          Vec3(-0.0f, 0, 1), Vec3(0, -0.0f, -1)})
        rays.push_back({center, d});
    const std::vector<Ray> more = rays_from_inside(sphere, center, radius, count, 5);
    rays.insert(rays.end(), more.begin(), more.end());
    return rays;
}

}  // namespace

TEST_CASE("rays from inside a closed tessellated sphere never leak", "[watertight]") {
    for (const auto& [center, radius] : {std::pair{Vec3(0), 1.0f}, std::pair{Vec3(1e5f, -1e5f, 1e5f), 10.0f},
                                         std::pair{Vec3(0), 1e-4f}, std::pair{Vec3(0), 1e4f}}) {
        const std::vector<Triangle> sphere = closed_sphere(5, center, radius);
        INFO("sphere at " << center.x << " radius " << radius);
        CHECK(count_leaks(sphere, rays_from_center(sphere, center, radius, 20000)) == 0);
    }
}

TEST_CASE("rays aimed exactly at shared edges and vertices of a plane never leak", "[watertight]") {
    for (const auto& [scale, offset] : {std::pair{1.0f, Vec3(0)}, std::pair{1.0f, Vec3(1e5f, 1e5f, 0)},
                                        std::pair{1e-4f, Vec3(0)}, std::pair{1e4f, Vec3(0)}}) {
        const int n = 64;
        const std::vector<Triangle> plane = tessellated_plane(n, scale, offset);
        std::mt19937_64 rng(11);
        std::uniform_real_distribution<float> u(-1.0f, 1.0f);
        std::vector<Ray> rays;
        for (int j = 1; j < n; ++j)
            for (int i = 1; i < n; ++i) {
                // A vertex, the midpoints of the horizontal, vertical and diagonal edges next to it.
                for (const Vec3& local : {Vec3(i, j, 0), Vec3(i + 0.5f, j, 0), Vec3(i, j + 0.5f, 0), Vec3(i + 0.5f, j + 0.5f, 0)}) {
                    const Vec3 target = offset + scale * local;
                    rays.push_back({target + Vec3(0, 0, scale), {-0.0f, 0.0f, -1.0f}});  // straight down
                    const Vec3 from = target + scale * Vec3(u(rng), u(rng), 1.0f + std::abs(u(rng)));
                    rays.push_back({from, glm::normalize(target - from)});
                }
            }
        INFO("plane scale " << scale << " offset " << offset.x);
        CHECK(count_leaks(plane, rays) == 0);
    }
}

TEST_CASE("translated and scaled scenes agree with brute force", "[extreme][heavy]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=12"));
    for (const auto& [scale, offset] : {std::pair{1.0f, Vec3(1e5f, 1e5f, 1e5f)}, std::pair{1e-4f, Vec3(0)},
                                        std::pair{1e4f, Vec3(0)}, std::pair{1e-4f, Vec3(-1e5f, 0, 1e5f)}}) {
        const std::vector<Triangle> tris = transformed(flat.triangles, scale, offset);
        check_against_oracle(tris, random_rays(tris, test::scaled(20000, 2000), 31), "box x" + std::to_string(scale));
    }
}

TEST_CASE("zero and negative-zero direction components agree with brute force", "[extreme]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=13"));
    std::vector<Ray> rays = random_rays(flat.triangles, 20000, 37);
    const float zeros[] = {0.0f, -0.0f};
    for (size_t i = 0; i < rays.size(); ++i) {
        Vec3& d = rays[i].dir;
        d[i % 3] = zeros[(i / 3) % 2];
        if (i % 7 == 0) d[(i + 1) % 3] = zeros[(i / 7) % 2];  // two zero components: axis-aligned
        if (glm::dot(d, d) == 0.0f) d[(i + 2) % 3] = 1.0f;
        d = glm::normalize(d);
        d[i % 3] = zeros[(i / 3) % 2];  // normalize turns -0 into 0: set it again
    }
    check_against_oracle(flat.triangles, rays, "box, zero components");
}

// A NaN direction component disables its axis in the node test (SlabRay): no crash, no hit, in any kernel.
TEST_CASE("rays with NaN direction components hit nothing and never crash", "[extreme]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=15"));
    const BuiltScene built = build_with("binned", flat.triangles);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const Vec3 inside = BBox::of(flat.triangles[0]).center();
    for (const KernelUnderTest& kernel : kernels_of(built))
        for (const Vec3& dir : {Vec3(nan, 0, 1), Vec3(nan, nan, nan), Vec3(-nan, 1, 0), Vec3(0, nan, -nan)}) {
            INFO(kernel.name << " direction " << dir.x << " " << dir.y << " " << dir.z);
            CHECK(!kernel.closest(Ray{inside, dir}).found());
            CHECK(!kernel.any(Ray{inside, dir}));
        }
}

TEST_CASE("degenerate triangles are built and traced without harm", "[extreme]") {
    const FlatScene flat = flatten(load_scene("gen:surface?tris=3000&seed=14"));
    std::vector<Triangle> tris = flat.triangles;
    std::mt19937_64 rng(41);
    for (size_t i = 0; i < 2000; ++i) {
        const Triangle& t = flat.triangles[rng() % flat.triangles.size()];
        if (i % 2) tris.push_back({t.v0, t.v0, t.v0});                      // a point
        else tris.push_back({t.v0, t.v1, t.v0 + 2.0f * (t.v1 - t.v0)});    // collinear
    }
    for (int i = 0; i < 500; ++i) tris.push_back({Vec3(0.5f), Vec3(0.5f), Vec3(0.5f)});  // coincident centroids
    check_against_oracle(tris, random_rays(tris, 20000, 43), "surface + degenerate");
}

TEST_CASE("rays grazing triangle edges and flat boxes agree with brute force", "[extreme]") {
    // An axis-aligned plane gives flat node boxes; rays travel inside the plane, along edges and just off it.
    const std::vector<Triangle> plane = tessellated_plane(16, 1.0f, Vec3(0));
    std::vector<Ray> rays;
    for (int k = 0; k <= 16; ++k) {
        const float c = float(k);
        rays.push_back({{-1.0f, c, 0.0f}, {1.0f, 0.0f, 0.0f}});             // along a row of edges, in the plane
        rays.push_back({{c, -1.0f, 0.0f}, {0.0f, 1.0f, -0.0f}});            // along a column of edges
        rays.push_back({{-1.0f, c, 1e-7f}, {1.0f, 0.0f, 0.0f}});            // just above the plane
        rays.push_back({{-1.0f, -1.0f, 0.0f}, glm::normalize(Vec3(1, 1, 0))});  // along the diagonals
        rays.push_back({{c, c, 1.0f}, glm::normalize(Vec3(1e-7f, 0, -1))});  // nearly vertical onto a vertex
        rays.push_back({{-1.0f, c + 0.5f, 0.5f}, glm::normalize(Vec3(1, 0, -0.5f / (c + 1.0f)))});  // shallow
    }
    check_against_oracle(plane, rays, "grazing plane");
}

TEST_CASE("the accuracy measurement: watertight kernels never leak at the extremes of scale and offset", "[accuracy]") {
    AccuracyOptions options;
    options.rays = 30000;
    options.sphere_levels = 4;
    const std::vector<AccuracyRow> rows = measure_accuracy(options, {{1e-6, 0.0}, {1e6, 0.0}, {100.0, 1e7}, {1e-2, 1e3}});
    REQUIRE(rows.size() == 16);
    for (const AccuracyRow& row : rows) {
        INFO(row.mode << " radius " << row.where.scale << " offset " << row.where.offset);
        const bool watertight_robust = row.mode.find(" mt") == std::string::npos && row.mode.find("fast") == std::string::npos;
        if (watertight_robust) CHECK(row.leaks == 0);
        // A float hit distance within a few ulps of the exact one, whatever the scale or offset.
        CHECK(row.t_error_max < 1e-5);
        CHECK(row.point_error_ulps < 16.0);
    }
}

// Rays from inside a sphere far out: every ray drawn, every direction finite and of unit length, up to where float
// cannot tell the sphere's points apart (there, an error rather than a loop that never ends).
TEST_CASE("rays from inside small spheres far out all have directions, or are refused", "[accuracy]") {
    for (const double offset : {1e8, 1e9, 1e12}) {
        INFO("offset " << offset);
        const Vec3 center = float(offset) * Vec3(1, -1, 1);
        const std::vector<Triangle> sphere = closed_sphere(2, center, 100.0f * float(offset) * 1e-6f);
        const std::vector<Ray> rays = rays_from_inside(sphere, center, 100.0f * float(offset) * 1e-6f, 3000, 7);
        REQUIRE(rays.size() == 3000);
        for (const Ray& ray : rays) CHECK(std::abs(glm::length(ray.dir) - 1.0f) < 1e-5f);
    }
    const Vec3 far = 1e9f * Vec3(1, -1, 1);
    CHECK_THROWS_AS(rays_from_inside(closed_sphere(2, far, 1.0f), far, 1.0f, 3000, 7), std::invalid_argument);
}

// Planes are stored relative to a frame at each tree's centre and the ray's origin translated to it (PlaneFrame):
// small spheres far out, in every kernel width.
TEST_CASE("robust watertight kernels never leak from a small sphere far from the origin, in every width", "[accuracy]") {
    AccuracyOptions options;
    options.rays = 20000;
    options.sphere_levels = 4;
    for (const char* kernel : {"bvh2", "bvh4", "bvh8"}) {
        options.kernel = kernel;
        const std::vector<AccuracyRow> rows = measure_accuracy(options, {{100.0, 1e7}, {1.0, 1e5}, {1e4, 1e7}});
        for (const AccuracyRow& row : rows) {
            INFO(row.mode << " radius " << row.where.scale << " offset " << row.where.offset);
            const bool watertight_robust = row.mode.find(" mt") == std::string::npos && row.mode.find("fast") == std::string::npos;
            if (watertight_robust) CHECK(row.leaks == 0);
        }
    }
}
