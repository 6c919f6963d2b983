#pragma once
// Test support: brute-force closest hit over all triangles, random test rays, and the comparison
// rule of the oracle tests (same triangle, or the same distance within 1e-5 where triangles tie).
#include "accel/builder.h"
#include "accel/builders/lbvh_direct.h"
#include "kernels/dispatch.h"
#include "kernels/traverse.h"
#include "scenes/scene.h"

#include <catch2/catch.hpp>
#include <tbb/parallel_for.h>

#include <filesystem>
#include <random>
#include <span>
#include <string>
#include <vector>

namespace canopy::test {

template <class TriangleTest = WatertightRay>
Hit brute_force_closest(std::span<const Triangle> tris, const Ray& ray) {
    const TriangleTest wt(ray);
    Hit hit;
    hit.t = ray.tmax;
    for (uint32_t i = 0; i < tris.size(); ++i) wt.intersect(tris[i].v0, tris[i].v1, tris[i].v2, i, ray.tmin, hit);
    return hit;
}

// A path tracer's tracer that answers by brute force, so that a test of shading depends on shading alone; its any
// hit is a closest hit within the ray's interval.
struct BruteForceTracer {
    std::span<const Triangle> triangles;
    bool closest(const Ray& ray, Hit& hit) const {
        hit = brute_force_closest(triangles, ray);
        return hit.found();
    }
};

// The inside of the cube [-1, 1]^3 in 12 triangles, two a face: -z, +z, -y, +y, -x, +x.
inline std::vector<Triangle> cube_inside() {
    const Vec3 p[8] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}};
    const int faces[6][4] = {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {3, 2, 6, 7}, {0, 3, 7, 4}, {1, 2, 6, 5}};
    std::vector<Triangle> triangles;
    for (const auto& f : faces) {
        triangles.push_back({p[f[0]], p[f[1]], p[f[2]]});
        triangles.push_back({p[f[0]], p[f[2]], p[f[3]]});
    }
    return triangles;
}

template <class TriangleTest = WatertightRay>
std::vector<Hit> brute_force_all(std::span<const Triangle> tris, const std::vector<Ray>& rays) {
    std::vector<Hit> hits(rays.size());
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) { hits[i] = brute_force_closest<TriangleTest>(tris, rays[i]); });
    return hits;
}

// Random rays of four kinds, a quarter each: origin inside or outside the bounds, direction
// uniformly random or from a point on one triangle towards a point on another.
inline std::vector<Ray> random_rays(std::span<const Triangle> tris, size_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    BBox bounds;
    for (const Triangle& t : tris) bounds.extend(BBox::of(t));
    const Vec3 center = bounds.center();
    const float radius = glm::length(bounds.extent());
    auto sphere = [&] {
        const float z = 2.0f * unit(rng) - 1.0f, phi = 6.2831853f * unit(rng), r = std::sqrt(std::max(0.0f, 1 - z * z));
        return Vec3(r * std::cos(phi), r * std::sin(phi), z);
    };
    auto on_triangle = [&] {
        const Triangle& t = tris[rng() % tris.size()];
        float a = unit(rng), b = unit(rng);
        if (a + b > 1.0f) a = 1.0f - a, b = 1.0f - b;
        return t.v0 + a * (t.v1 - t.v0) + b * (t.v2 - t.v0);
    };
    std::vector<Ray> rays;
    rays.reserve(count);
    for (size_t i = 0; i < count; ++i) {
        Ray ray;
        switch (i % 4) {
            case 0: ray.org = bounds.lower + Vec3(unit(rng), unit(rng), unit(rng)) * bounds.extent(); ray.dir = sphere(); break;
            case 1: ray.org = center + radius * sphere(); ray.dir = sphere(); break;
            case 2: ray.org = center + radius * sphere(); ray.dir = glm::normalize(on_triangle() - ray.org); break;
            default: {
                ray.org = on_triangle();
                const Vec3 to = on_triangle();
                ray.dir = to == ray.org ? sphere() : glm::normalize(to - ray.org);
            }
        }
        rays.push_back(ray);
    }
    return rays;
}

// `tris` a thousand times their extent from the origin along x, then scaled by `scale`: the extremes of the layouts'
// plane frames and quantisation.
inline std::vector<Triangle> scaled_far_from_origin(std::vector<Triangle> tris, float scale) {
    BBox bounds;
    for (const Triangle& t : tris) bounds.extend(BBox::of(t));
    const Vec3 offset(1000.0f * glm::length(bounds.extent()), 0.0f, 0.0f);
    for (Triangle& t : tris)
        for (Vec3* v : {&t.v0, &t.v1, &t.v2}) *v = scale * (*v + offset);
    return tris;
}

// `count` rays aimed at shared corners and edge midpoints, from a few units of `scale` away.
inline std::vector<Ray> corner_and_edge_rays(std::span<const Triangle> tris, size_t count, float scale) {
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        const Triangle& t = tris[(i * 7919) % tris.size()];
        const Vec3 target = i % 2 ? t.v0 : 0.5f * (t.v1 + t.v2);
        const Vec3 org = target + scale * Vec3(3.0f, 2.0f + float(i % 5), -4.0f);
        rays.push_back({org, target - org});
    }
    return rays;
}

// random_rays with bounded intervals: every third starts 5% of the scene's diagonal along, every other one ends at
// 30% of it.
inline std::vector<Ray> bounded_interval_rays(const FlatScene& flat, size_t count, uint64_t seed) {
    std::vector<Ray> rays = random_rays(flat.triangles, count, seed);
    const float diagonal = glm::length(flat.bounds.extent());
    for (size_t i = 0; i < rays.size(); ++i) {
        rays[i].tmin = (i % 3 == 0) ? 0.05f * diagonal : 0.0f;
        rays[i].tmax = (i % 2 == 0) ? 0.3f * diagonal : rays[i].tmax;
    }
    return rays;
}

// The oracle tests' shared scenes, each flattened and passed to check(flat, name); an absent one is a warning.
template <class Check>
void for_each_shared_scene(Check&& check) {
    for (const char* name : {"stanford-bunny", "sibenik", "crytek-sponza"}) {
        const std::filesystem::path path = std::filesystem::path(CANOPY_SHARED_SCENES) / name / "scene.json";
        if (!std::filesystem::exists(path)) {
            WARN("skipped: " << path << " is absent");
            continue;
        }
        check(flatten(load_scene(path.string())), name);
    }
}

// The rays of random_rays whose origin is not on a surface (kinds 0 to 2). A ray from one point of a flat
// wall to another lies in the plane of the wall's triangles; only the watertight test is exact there.
inline std::vector<Ray> off_surface(const std::vector<Ray>& rays) {
    std::vector<Ray> out;
    for (size_t i = 0; i < rays.size(); ++i)
        if (i % 4 != 3) out.push_back(rays[i]);
    return out;
}

// Counts disagreements between a kernel's hits and the oracle's; reports the first few. The same triangle
// must be hit at exactly the same distance when the kernel rounds like the oracle (canopy's kernels), within
// 1e-5 relative otherwise; another triangle only at a tie, the same distance within 1e-5 relative.
inline size_t count_mismatches(const std::vector<Ray>& rays, const std::vector<Hit>& expected,
                               const std::vector<Hit>& actual, const std::string& what, bool same_rounding = true) {
    size_t mismatches = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit& e = expected[i];
        const Hit& a = actual[i];
        bool same = e.found() == a.found();
        const bool close = std::abs(e.t - a.t) <= 1e-5f * std::abs(e.t);
        if (same && e.found()) same = e.prim == a.prim && same_rounding ? e.t == a.t : close;
        if (!same && ++mismatches <= 3) {
            const Ray& r = rays[i];
            UNSCOPED_INFO(what << ": ray " << i << " org (" << r.org.x << ", " << r.org.y << ", " << r.org.z
                               << ") dir (" << r.dir.x << ", " << r.dir.y << ", " << r.dir.z << "): expected prim "
                               << e.prim << " t " << e.t << ", got prim " << a.prim << " t " << a.t);
        }
    }
    return mismatches;
}

// Every registered builder with every kernel, as ready-to-trace closures.
struct KernelUnderTest {
    std::string name;
    std::function<Hit(const Ray&)> closest;
    std::function<bool(const Ray&)> any;
};

struct BuiltScene {
    Bvh binary;
    WideBvh<2> bvh2;
    WideBvh<4> bvh4;
    WideBvh<8> bvh8;
    bool has_bvh2 = true;  // false for lbvh's direct wide trees, which have neither binary tree nor bvh2
};

inline BuiltScene build_with(const std::string& builder, std::span<const Triangle> tris) {
    BuiltScene built;
    built.binary = find_builder(builder).build(BuildInput{tris, make_prim_refs(tris)}, BuildSettings{});
    built.bvh2 = collapse<2>(built.binary, tris);
    if constexpr (kernel_compiled(4)) built.bvh4 = collapse<4>(built.binary, tris);
    if constexpr (kernel_compiled(8)) built.bvh8 = collapse<8>(built.binary, tris);
    return built;
}

// lbvh's wide trees emitted straight from the Morton codes (collapse 'direct'), in bvh4's and bvh8's places.
inline BuiltScene build_direct(std::span<const Triangle> tris) {
    BuiltScene built;
    built.has_bvh2 = false;
    if constexpr (kernel_compiled(4)) built.bvh4 = build_wide_lbvh<4>(BuildInput{tris, make_prim_refs(tris)});
    if constexpr (kernel_compiled(8)) built.bvh8 = build_wide_lbvh<8>(BuildInput{tris, make_prim_refs(tris)});
    return built;
}

template <bool Robust, class TriangleTest, int N>
void add_kernel(std::vector<KernelUnderTest>& kernels, const WideBvh<N>& bvh) {
    if constexpr (kernel_compiled(N)) {
        if (!cpu_runs(N)) return;
        kernels.push_back({kernel_name(N),
                           [&bvh](const Ray& r) { Hit h; closest_hit<Robust, TriangleTest>(bvh, r, h); return h; },
                           [&bvh](const Ray& r) { return any_hit<Robust, TriangleTest>(bvh, r); }});
    }
}

// Every kernel this build and CPU run, over one built scene, in the given traversal and intersection modes.
template <bool Robust = true, class TriangleTest = WatertightRay>
std::vector<KernelUnderTest> kernels_of(const BuiltScene& built) {
    std::vector<KernelUnderTest> kernels;
    if (built.has_bvh2) add_kernel<Robust, TriangleTest>(kernels, built.bvh2);
    add_kernel<Robust, TriangleTest>(kernels, built.bvh4);
    add_kernel<Robust, TriangleTest>(kernels, built.bvh8);
    return kernels;
}

// Checks every builder x kernel against the oracle on `rays`, and lbvh's direct wide trees with theirs: closest
// hits, and any-hit agreement. At most `allowed` rays may disagree (0 but for the non-conservative fast traversal).
template <bool Robust = true, class TriangleTest = WatertightRay>
void check_against_oracle(std::span<const Triangle> tris, const std::vector<Ray>& rays, const std::string& scene,
                          size_t allowed = 0) {
    const std::vector<Hit> expected = brute_force_all<TriangleTest>(tris, rays);
    const auto check = [&](const std::string& name, const BuiltScene& built) {
        for (const KernelUnderTest& kernel : kernels_of<Robust, TriangleTest>(built)) {
            const std::string what = scene + " / " + name + " / " + kernel.name;
            std::vector<Hit> actual(rays.size());
            std::vector<char> any(rays.size());
            tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) {
                actual[i] = kernel.closest(rays[i]);
                any[i] = kernel.any(rays[i]);
            });
            CHECK(count_mismatches(rays, expected, actual, what) <= allowed);
            size_t any_mismatches = 0;
            for (size_t i = 0; i < rays.size(); ++i) any_mismatches += bool(any[i]) != expected[i].found();
            INFO(what << ": any-hit disagreements");
            CHECK(any_mismatches <= allowed);
        }
    };
    for (const BuilderEntry& builder : builders()) check(builder.name, build_with(builder.name, tris));
    check("lbvh direct", build_direct(tris));
}

}  // namespace canopy::test
