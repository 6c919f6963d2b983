// The walks behind the API's ray lists and point queries (kernels/all_hits.h, kernels/closest_point.h), on every
// builder and width, against brute force over every triangle.
#include "kernels/closest_point.h"
#include "oracle.h"

#include <algorithm>
#include <set>

using namespace canopy;
using namespace canopy::test;

namespace {

// The triangles the test hits in the ray's interval, by trying every one.
template <class TriangleTest>
std::set<uint32_t> brute_force_hits(std::span<const Triangle> tris, const Ray& ray) {
    const TriangleTest test(ray);
    std::set<uint32_t> hit;
    for (uint32_t i = 0; i < tris.size(); ++i) {
        Hit h;
        h.t = ray.tmax;
        if (test.intersect(tris[i].v0, tris[i].v1, tris[i].v2, i, kernel_tmin(ray), h)) hit.insert(i);
    }
    return hit;
}

template <bool Robust, class TriangleTest, int N>
std::set<uint32_t> walked_hits(const WideBvh<N>& bvh, const Ray& ray) {
    std::set<uint32_t> hit;
    for_each_hit<Robust, TriangleTest>(bvh, ray, [&](const Hit& h, const Triangle&) { hit.insert(h.prim); });
    return hit;
}

// Calls f(tree) with each width this build and CPU run.
template <class F>
void for_each_width(const BuiltScene& built, F&& f) {
    if (built.has_bvh2) f(built.bvh2);
    if constexpr (kernel_compiled(4))
        if (cpu_runs(4)) f(built.bvh4);
    if constexpr (kernel_compiled(8))
        if (cpu_runs(8)) f(built.bvh8);
}

// Random rays, bounded intervals, and rays through shared corners and edges, where a triangle test is most tested.
constexpr size_t kRandomRays = 1500;
std::vector<Ray> adversarial_rays(const FlatScene& flat) {
    std::vector<Ray> rays = bounded_interval_rays(flat, kRandomRays, 5);
    for (const Ray& r : corner_and_edge_rays(flat.triangles, 500, 0.01f)) rays.push_back(r);
    return rays;
}

// Independent of Ericson's region test: the projection on the plane when it falls inside, else the nearest point of
// the three edges, all in double.
double reference_distance2(const DVec3& p, const Triangle& t) {
    const DVec3 a(t.v0), b(t.v1), c(t.v2);
    const DVec3 n = glm::cross(b - a, c - a);
    const double n2 = glm::dot(n, n);
    if (n2 > 0.0) {
        const DVec3 q = p - glm::dot(p - a, n) / n2 * n;
        const double wa = glm::dot(glm::cross(b - q, c - q), n), wb = glm::dot(glm::cross(c - q, a - q), n),
                     wc = glm::dot(glm::cross(a - q, b - q), n);
        if (wa >= 0.0 && wb >= 0.0 && wc >= 0.0) return glm::dot(p - q, p - q);
    }
    double best = std::numeric_limits<double>::infinity();
    for (const auto& [from, to] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
        const DVec3 q = from + segment_weight(p, from, to) * (to - from);
        best = std::min(best, glm::dot(p - q, p - q));
    }
    return best;
}

// Query points: uniform in the scene's box grown by half, on and beside surfaces, and far away.
std::vector<DVec3> query_points(const FlatScene& flat, size_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const DVec3 lower(flat.bounds.lower), extent(flat.bounds.extent());
    std::vector<DVec3> points;
    for (size_t i = 0; i < count; ++i) {
        const Triangle& t = flat.triangles[rng() % flat.triangles.size()];
        const DVec3 on = DVec3(t.v0) + 0.3 * DVec3(t.v1 - t.v0) + 0.3 * DVec3(t.v2 - t.v0);
        switch (i % 4) {
            case 0: points.push_back(lower - 0.25 * extent + 1.5 * extent * DVec3(unit(rng), unit(rng), unit(rng))); break;
            case 1: points.push_back(on); break;
            case 2: points.push_back(on + 1e-4 * glm::length(extent) * DVec3(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5)); break;
            default: points.push_back(lower + 1e6 * glm::length(extent) * DVec3(unit(rng) - 0.5, unit(rng), -unit(rng)));
        }
    }
    return points;
}

}  // namespace

TEST_CASE("every hit: each builder and width lists exactly the triangles brute force hits", "[point-queries]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=21"));
    const std::vector<Ray> rays = adversarial_rays(flat);
    std::vector<std::set<uint32_t>> watertight(rays.size()), moller(rays.size());
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) {
        watertight[i] = brute_force_hits<WatertightRay>(flat.triangles, rays[i]);
        moller[i] = brute_force_hits<MollerTrumboreRay>(flat.triangles, rays[i]);
    });
    size_t listed = 0;
    for (const BuilderEntry& builder : builders()) {
        for_each_width(build_with(builder.name, flat.triangles), [&]<int N>(const WideBvh<N>& bvh) {
            INFO(builder.name << " / bvh" << N);
            for (size_t i = 0; i < rays.size(); ++i) {
                const std::set<uint32_t> hits = walked_hits<true, WatertightRay>(bvh, rays[i]);
                REQUIRE(hits == watertight[i]);
                // Möller–Trumbore's hits of a ray in a triangle's plane (random_rays' kind 3 runs from surface to
                // surface) are rounding, at any distance: only the watertight test is exact there.
                if (i >= kRandomRays || i % 4 != 3) REQUIRE(walked_hits<true, MollerTrumboreRay>(bvh, rays[i]) == moller[i]);
                listed += hits.size();
            }
        });
    }
    CHECK(listed > 10 * rays.size());  // most rays cross the box's walls more than once
}

TEST_CASE("every hit: the first is the closest hit's triangle or ties with it", "[point-queries]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=22"));
    const BuiltScene built = build_with("sbvh", flat.triangles);
    for_each_width(built, [&]<int N>(const WideBvh<N>& bvh) {
        for (const Ray& ray : random_rays(flat.triangles, 2000, 23)) {
            Hit closest;
            closest_hit(bvh, ray, closest);
            Hit first;
            for_each_hit<true, WatertightRay>(bvh, ray, [&](const Hit& h, const Triangle&) {
                if (h.t < first.t || (h.t == first.t && h.prim < first.prim)) first = h;
            });
            INFO("bvh" << N);
            REQUIRE(first.found() == closest.found());
            REQUIRE(first.t == closest.t);
        }
    });
}

TEST_CASE("closest points: Ericson's region test agrees with projection and edges, degenerate triangles included",
          "[point-queries][extreme]") {
    std::mt19937_64 rng(24);
    std::normal_distribution<float> normal;
    size_t checked = 0;
    for (int i = 0; i < 20000; ++i) {
        Triangle t{Vec3(normal(rng), normal(rng), normal(rng)), Vec3(normal(rng), normal(rng), normal(rng)),
                   Vec3(normal(rng), normal(rng), normal(rng))};
        if (i % 5 == 1) t.v2 = t.v1;                          // a segment
        if (i % 5 == 2) t.v2 = t.v0 + 2.0f * (t.v1 - t.v0);   // collinear corners
        if (i % 5 == 3) t.v1 = t.v2 = t.v0;                   // a point
        const DVec3 p = 3.0 * DVec3(normal(rng), normal(rng), normal(rng));
        const auto [u, v] = closest_weights(p, DVec3(t.v0), DVec3(t.v1), DVec3(t.v2));
        REQUIRE(u >= 0.0);
        REQUIRE(v >= 0.0);
        REQUIRE(u + v <= 1.0 + 1e-12);
        const DVec3 q = DVec3(t.v0) + u * (DVec3(t.v1) - DVec3(t.v0)) + v * (DVec3(t.v2) - DVec3(t.v0));
        const double expected = std::sqrt(reference_distance2(p, t));
        REQUIRE(std::abs(glm::length(q - p) - expected) <= 1e-9 * (1.0 + expected));  // a wrong region errs by O(1)
        ++checked;
    }
    CHECK(checked == 20000);
}

TEST_CASE("closest points: each builder and width finds brute force's nearest triangle and distance",
          "[point-queries]") {
    FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=25"));
    flat.triangles.push_back({Vec3(0.1f), Vec3(0.1f), Vec3(0.1f)});  // a zero-area triangle as a leaf's neighbour
    const std::vector<DVec3> points = query_points(flat, 2000, 26);
    std::vector<std::pair<double, uint32_t>> expected(points.size());
    tbb::parallel_for(size_t(0), points.size(), [&](size_t i) {
        expected[i] = {std::numeric_limits<double>::infinity(), Hit::kNone};
        for (uint32_t k = 0; k < flat.triangles.size(); ++k) {
            const Triangle& t = flat.triangles[k];
            const auto [u, v] = closest_weights(points[i], DVec3(t.v0), DVec3(t.v1), DVec3(t.v2));
            const DVec3 q = DVec3(t.v0) + u * (DVec3(t.v1) - DVec3(t.v0)) + v * (DVec3(t.v2) - DVec3(t.v0));
            const std::pair<double, uint32_t> candidate{glm::dot(q - points[i], q - points[i]), k};
            expected[i] = std::min(expected[i], candidate);
        }
    });
    for (const BuilderEntry& builder : builders()) {
        for_each_width(build_with(builder.name, flat.triangles), [&]<int N>(const WideBvh<N>& bvh) {
            INFO(builder.name << " / bvh" << N);
            for (size_t i = 0; i < points.size(); ++i) {
                const PointHit hit = closest_point(bvh, points[i]);
                REQUIRE(hit.distance2 == expected[i].first);
                REQUIRE(hit.prim == expected[i].second);  // ties go to the lowest triangle id, as min does
                const Triangle& t = flat.triangles[hit.prim];
                const DVec3 q = DVec3(t.v0) + hit.u * (DVec3(t.v1) - DVec3(t.v0)) + hit.v * (DVec3(t.v2) - DVec3(t.v0));
                REQUIRE(glm::length(q - hit.point) <= 1e-12 * (1.0 + glm::length(q)));
            }
        });
    }
}

TEST_CASE("closest points: a bound stops the walk, and an empty tree finds nothing", "[point-queries]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=500&seed=27"));
    const BuiltScene built = build_with("binned", flat.triangles);
    const DVec3 far_away = DVec3(flat.bounds.upper) + DVec3(10.0 * glm::length(flat.bounds.extent()));
    CHECK_FALSE(closest_point(built.bvh2, far_away, 1.0).found());
    CHECK(closest_point(built.bvh2, far_away).found());
    CHECK_FALSE(closest_point(WideBvh<2>{}, far_away).found());
}
