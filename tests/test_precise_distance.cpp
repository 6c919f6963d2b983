// precise_t (kernels/precise_distance.h): float precision for short hits however big, far out or grazed the
// triangle, and the t = 0 rule: an origin exactly on a triangle never hits it.
#include "oracle.h"
#include "experiments/accuracy.h"
#include "kernels/precise_distance.h"

#include <cmath>
#include <numbers>

using namespace canopy;
using namespace canopy::test;

namespace {

// The distance to the triangle's plane in long double, 11 bits beyond precise_t's double: within 1e-8 of exact on
// the hits below (measured against quadruple precision), far under the float rounding asserted.
long double long_double_distance(const Triangle& t, const Ray& ray) {
    using LongVec3 = glm::vec<3, long double>;
    const LongVec3 v0(t.v0), n = glm::cross(LongVec3(t.v1) - v0, LongVec3(t.v2) - v0);
    return glm::dot(n, v0 - LongVec3(ray.org)) / glm::dot(n, LongVec3(ray.dir));
}

glm::dvec3 random_unit(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const double z = 2.0 * unit(rng) - 1.0, phi = 2.0 * std::numbers::pi * unit(rng), r = std::sqrt(1.0 - z * z);
    return {r * std::cos(phi), r * std::sin(phi), z};
}

// A triangle of circumradius `size` about `center`, in a random plane.
Triangle big_triangle(const glm::dvec3& center, double size, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> jitter(0.0, 0.3);
    const glm::dvec3 normal = random_unit(rng);
    const glm::dvec3 a = glm::normalize(glm::cross(normal, random_unit(rng))), b = glm::cross(normal, a);
    Vec3 v[3];
    for (int k = 0; k < 3; ++k) {
        const double angle = 2.0 * std::numbers::pi * (k + jitter(rng)) / 3.0;
        v[k] = Vec3(center + size * (std::cos(angle) * a + std::sin(angle) * b));
    }
    return {v[0], v[1], v[2]};
}

// A ray onto an interior point of the triangle from 1e-9 to 1e-2 of its size away, from either side, grazing (the
// direction's component along the normal 1e-6 to 1e-2) or not; the float origin's rounding moves it.
Ray short_ray(const Triangle& t, double size, std::mt19937_64& rng, bool grazing) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const glm::dvec3 v0(t.v0), e1 = glm::dvec3(t.v1) - v0, e2 = glm::dvec3(t.v2) - v0;
    const glm::dvec3 point = v0 + (0.1 + 0.4 * unit(rng)) * e1 + (0.1 + 0.4 * unit(rng)) * e2;
    const glm::dvec3 normal = glm::normalize(glm::cross(e1, e2)), along = glm::normalize(glm::cross(normal, random_unit(rng)));
    const double cosine = grazing ? std::pow(10.0, -6.0 + 4.0 * unit(rng)) : 0.1 + 0.9 * unit(rng);
    const double side = unit(rng) < 0.5 ? 1.0 : -1.0;
    const glm::dvec3 dir = side * (-cosine * normal + std::sqrt(1.0 - cosine * cosine) * along);
    const double distance = size * std::pow(10.0, -9.0 + 7.0 * unit(rng));
    return {Vec3(point - distance * dir), Vec3(dir)};
}

// The closest hit of `tris` by the rule's protocol, as the public API applies it: a kernel hit whose precise t is not
// beyond tmin does not count, and the ray is traced again from that hit's float t (the interval is (tmin, tmax]).
Hit counting_closest_hit(std::span<const Triangle> tris, Ray ray) {
    for (;;) {
        Hit hit = brute_force_closest(tris, ray);
        if (!hit.found() || precise_hit_counts(precise_t(tris[hit.prim], ray), ray.tmin)) return hit;
        ray.tmin = hit.t;
    }
}

bool counts(const Triangle& t, const Ray& ray) { return precise_hit_counts(precise_t(t, ray), ray.tmin); }

// Directions to both sides of the triangle's plane, and along two of its edges (in the plane but for rounding).
std::vector<Vec3> directions_about(const Triangle& t, std::mt19937_64& rng) {
    std::vector<Vec3> dirs = {glm::normalize(geometric_normal(t)), -glm::normalize(geometric_normal(t)),
                              glm::normalize(t.v1 - t.v0), glm::normalize(t.v2 - t.v1)};
    for (int i = 0; i < 4; ++i) dirs.push_back(Vec3(random_unit(rng)));
    return dirs;
}

}  // namespace

TEST_CASE("precise_t keeps float precision on short hits where the kernel's t does not", "[precise]") {
    std::mt19937_64 rng(17);
    double kernel_worst = 0.0;
    for (const double offset : {0.0, 1e3, 1e5, 1e7}) {
        for (const double size : {1e2, 1e4, 1e6}) {
            size_t hits = 0;
            double precise_worst = 0.0;
            for (int k = 0; k < 8; ++k) {
                const Triangle t = big_triangle(offset * glm::dvec3(1, -1, 1), size, rng);
                for (int i = 0; i < 1000; ++i) {
                    const Ray ray = short_ray(t, size, rng, i % 2 == 0);
                    Hit hit;
                    if (!WatertightRay(ray).intersect(t.v0, t.v1, t.v2, 0, ray.tmin, hit)) continue;  // the kernel decides
                    const long double exact = long_double_distance(t, ray);
                    if (exact < 1e-9 * size) continue;  // the origin rounded onto or behind the plane
                    ++hits;
                    const auto relative_error = [exact](long double distance) { return double(std::abs(distance - exact) / exact); };
                    precise_worst = std::max(precise_worst, relative_error(precise_t_float(t.v0, t.v1, t.v2, ray)));
                    kernel_worst = std::max(kernel_worst, relative_error(hit.t));
                }
            }
            INFO("offset " << offset << ", triangle size " << size << ", " << hits << " hits");
            CHECK(hits > 1000);
            CHECK(precise_worst < 1e-7);  // float's rounding, 2^-24 = 6e-8, and the oracle's error
        }
    }
    CHECK(kernel_worst > 1.0);  // the cases are adversarial: somewhere the kernel's t is off by more than t
}

TEST_CASE("the t = 0 rule: an origin exactly on an axis-aligned triangle never hits it", "[precise]") {
    std::mt19937_64 rng(3);
    for (const float offset : {0.0f, 1.0f, 1e4f, 1e7f}) {
        const float z = offset + 0.375f;
        const Triangle t{{offset, offset, z}, {offset + 64.0f, offset, z}, {offset, offset + 64.0f, z}};
        INFO("offset " << offset);
        for (const Vec3& origin : {Vec3(offset + 1.0f, offset + 1.0f, z), Vec3(offset + 20.0f, offset + 7.5f, z), t.v1,
                                   Vec3(offset + 32.0f, offset + 32.0f, z)})
            for (const Vec3& dir : directions_about(t, rng)) CHECK_FALSE(counts(t, {origin, dir}));
        // A float above the plane, looking down: a hit at the exact distance, and it counts.
        const Ray above{{offset + 1.0f, offset + 1.0f, std::nextafter(z, INFINITY)}, {0.0f, 0.0f, -1.0f}};
        CHECK(precise_t(t, above) == double(above.org.z) - double(z));
        CHECK(counts(t, above));
    }
}

TEST_CASE("the t = 0 rule: an origin at a vertex or an exact edge midpoint never hits the triangle", "[precise]") {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<float> coordinate(-1.0f, 1.0f);
    size_t midpoints = 0;
    for (const float scale : {1e-3f, 1.0f, 1e3f})
        for (const float offset : {0.0f, 1e2f, 1e5f})
            for (int k = 0; k < 200; ++k) {
                Vec3 v[3];
                for (Vec3& p : v) p = offset + scale * Vec3(coordinate(rng), coordinate(rng), coordinate(rng));
                const Triangle t{v[0], v[1], v[2]};
                std::vector<Vec3> on_triangle(v, v + 3);
                for (int e = 0; e < 3; ++e) {
                    const Vec3 midpoint = 0.5f * (v[e] + v[(e + 1) % 3]);
                    if (glm::dvec3(midpoint) == 0.5 * (glm::dvec3(v[e]) + glm::dvec3(v[(e + 1) % 3])))
                        on_triangle.push_back(midpoint), ++midpoints;  // exact: on the edge, so on the plane
                }
                for (const Vec3& origin : on_triangle) {
                    for (const Vec3& dir : directions_about(t, rng)) {
                        INFO("scale " << scale << ", offset " << offset);
                        CHECK_FALSE(counts(t, {origin, dir}));
                    }
                }
            }
    CHECK(midpoints > 1000);  // of 5400 edges, those whose float midpoint is exact
}

TEST_CASE("the t = 0 rule's protocol: a ray from a shared edge finds the surface beyond, not its own", "[precise]") {
    // Two triangles of the plane z = 0 sharing the diagonal, and a square at z = -2 below them.
    const std::vector<Triangle> tris = {{{0, 0, 0}, {4, 0, 0}, {4, 4, 0}}, {{0, 0, 0}, {4, 4, 0}, {0, 4, 0}},
                                        {{-8, -8, -2}, {8, -8, -2}, {8, 8, -2}}, {{-8, -8, -2}, {8, 8, -2}, {-8, 8, -2}}};
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<float> along(0.0f, 4.0f), spread(-0.3f, 0.3f);
    for (int i = 0; i < 200; ++i) {
        const float s = along(rng);
        const Ray ray{{s, s, 0.0f}, glm::normalize(Vec3(spread(rng), spread(rng), -1.0f))};  // from the diagonal, down
        const Hit hit = counting_closest_hit(tris, ray);
        REQUIRE(hit.found());
        CHECK(hit.prim >= 2);
        CHECK(precise_t(tris[hit.prim], ray) == Approx(2.0 / -double(ray.dir.z)).epsilon(1e-7));
    }
}

TEST_CASE("canopy accuracy on a scene: short hits' precise_t within float rounding", "[precise][accuracy]") {
    AccuracyOptions options;
    options.rays = 20000;
    const std::vector<SceneAccuracyRow> rows = measure_scene_accuracy(options, "gen:room?tris=5000");
    REQUIRE(rows.size() == 2);  // watertight and Möller–Trumbore
    for (const SceneAccuracyRow& row : rows) {
        INFO(row.mode);
        CHECK(row.hits > 15000);
        CHECK(row.short_precise.hits > 500);
        CHECK(row.short_precise.max < 1e-7);
        CHECK(row.precise.max < 1e-7);
        CHECK(row.short_kernel.max > row.short_precise.max);
    }
}
