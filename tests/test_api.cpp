// The public C++ API as a consumer links it: include/canopy/canopy.h and libcanopy only. The engine underneath is
// tested against brute force in the other suites (and, through the Python module, in tests/python); these tests
// check what the API adds: batches split across threads, instance and triangle numbering, options, errors.
#include <canopy/canopy.h>

#include <catch2/catch.hpp>

#include <algorithm>
#include <bit>
#include <memory>
#include <cmath>
#include <random>

namespace {

struct Rays {
    std::vector<float> origins, directions;
    size_t count() const { return origins.size() / 3; }
    canopy::RayBatch batch() const { return {origins, directions, {}, {}}; }
};

// Origins in [-1.5, 1.5]^3 around the generated scenes (which fill [-1, 1]^3), random directions.
Rays random_rays(size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uniform(-1.5f, 1.5f);
    Rays rays;
    for (size_t i = 0; i < 3 * count; ++i) {
        rays.origins.push_back(uniform(rng));
        rays.directions.push_back(uniform(rng));
    }
    return rays;
}

std::vector<canopy::RayHit> batch_hits(const canopy::Accel& accel, const Rays& rays) {
    const size_t n = rays.count();
    std::vector<float> t(n), u(n), v(n);
    std::vector<uint32_t> triangle(n), instance(n);
    accel.intersect(rays.batch(), {t, triangle, u, v, instance});
    std::vector<canopy::RayHit> hits(n);
    for (size_t i = 0; i < n; ++i) hits[i] = {t[i], u[i], v[i], triangle[i], instance[i]};
    return hits;
}

std::array<float, 3> ray_point(const std::vector<float>& xyz, size_t i) { return {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}; }

bool same_bits(const canopy::RayHit& a, const canopy::RayHit& b) {
    return std::bit_cast<uint32_t>(a.t) == std::bit_cast<uint32_t>(b.t) && std::bit_cast<uint32_t>(a.u) == std::bit_cast<uint32_t>(b.u) &&
           std::bit_cast<uint32_t>(a.v) == std::bit_cast<uint32_t>(b.v) && a.triangle == b.triangle && a.instance == b.instance;
}

canopy::MeshArrays arrays(const canopy::TriangleMesh& mesh) { return {mesh.vertices, mesh.triangles}; }

// The cube [-1, 1]^3 as 12 triangles, outward: a closed mesh with a known distance function.
const canopy::TriangleMesh kCube{{-1, -1, -1, 1, -1, -1, 1, 1, -1, -1, 1, -1, -1, -1, 1, 1, -1, 1, 1, 1, 1, -1, 1, 1},
                                 {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 3, 7, 6, 3, 6, 2, 0, 4, 7, 0, 7, 3, 1, 2, 6, 1, 6, 5}};

// Requires two trees of one mesh to find every ray's hit at the same distance, bit for bit (the triangle may differ
// at ties); returns how many rays hit.
size_t same_distances(const canopy::Accel& a, const canopy::Accel& b, const Rays& rays) {
    const std::vector<canopy::RayHit> expected = batch_hits(a, rays), actual = batch_hits(b, rays);
    size_t found = 0;
    for (size_t i = 0; i < rays.count(); ++i) {
        REQUIRE(std::bit_cast<uint32_t>(actual[i].t) == std::bit_cast<uint32_t>(expected[i].t));
        REQUIRE(actual[i].found() == expected[i].found());
        found += actual[i].found();
    }
    return found;
}

}  // namespace

TEST_CASE("api: a batch answers each ray as the single-ray query does, bit for bit, on every kernel", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:surface?tris=3000&seed=3");
    const Rays rays = random_rays(5000, 1);
    for (const std::string builder : {"binned", "sbvh", "ploc"}) {
        for (const std::string kernel : {"bvh2", "bvh4", "bvh8"}) {
            INFO(builder << " " << kernel);
            const canopy::Accel accel(arrays(mesh), {.builder = builder, .kernel = kernel});
            const std::vector<canopy::RayHit> hits = batch_hits(accel, rays);
            std::unique_ptr<bool[]> any(new bool[rays.count()]);
            accel.occluded(rays.batch(), {any.get(), rays.count()});
            size_t found = 0;
            for (size_t i = 0; i < rays.count(); ++i) {
                const canopy::RayHit single = accel.intersect(ray_point(rays.origins, i), ray_point(rays.directions, i));
                REQUIRE(same_bits(hits[i], single));
                REQUIRE(any[i] == single.found());
                REQUIRE(accel.occluded(ray_point(rays.origins, i), ray_point(rays.directions, i)) == single.found());
                found += single.found();
            }
            REQUIRE(found > rays.count() / 4);
        }
    }
}

TEST_CASE("api: compressed nodes find the standard layout's hits, at the same distances bit for bit", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:surface?tris=3000&seed=3");
    const Rays rays = random_rays(5000, 4);
    const canopy::Accel standard(arrays(mesh), {.builder = "binned", .kernel = "bvh8"});
    const canopy::Accel compressed(arrays(mesh), {.builder = "binned", .kernel = "bvh8", .layout = "compressed"});
    REQUIRE(same_distances(standard, compressed, rays) > rays.count() / 4);
    CHECK(compressed.stats().kernel == "bvh8 compressed");
    CHECK(compressed.stats().bytes < standard.stats().bytes);
}

TEST_CASE("api: lbvh's default is the direct wide tree, the optimal collapse on request, with the same distances", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=3000&seed=5");
    const Rays rays = random_rays(5000, 6);
    const canopy::Accel direct(arrays(mesh), {.builder = "lbvh", .kernel = "bvh8"});
    const canopy::Accel collapsed(arrays(mesh), {.builder = "lbvh", .kernel = "bvh8", .collapse = "optimal"});
    REQUIRE(same_distances(collapsed, direct, rays) > rays.count() / 4);
    CHECK(direct.stats().kernel == "bvh8 direct");
    CHECK_FALSE(direct.stats().sah);  // no binary tree
    CHECK(collapsed.stats().kernel == "bvh8");
    CHECK(*collapsed.stats().sah > 0);
    CHECK(canopy::Accel(arrays(mesh), {.builder = "lbvh", .kernel = "bvh2"}).stats().kernel == "bvh2");
}

TEST_CASE("api: one thread and all threads give the same tree and hits", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:cylinders?tris=4000&seed=2");
    const Rays rays = random_rays(3000, 2);
    const std::vector<canopy::RayHit> all = batch_hits(canopy::Accel(arrays(mesh), {.builder = "sbvh"}), rays);
    const canopy::Accel one(arrays(mesh), {.builder = "sbvh", .threads = 1});
    const std::vector<canopy::RayHit> single_thread = batch_hits(one, rays);
    for (size_t i = 0; i < rays.count(); ++i) REQUIRE(same_bits(all[i], single_thread[i]));
    REQUIRE(one.stats().builder == "sbvh");
}

TEST_CASE("api: instances report their index and their mesh's triangle, at the world triangles' hits", "[api]") {
    // Two meshes, a generated surface (no triangles overlap, so no two tie) and one big triangle; three placements.
    const canopy::TriangleMesh surface = canopy::load_triangles("gen:surface?tris=500&seed=1");
    const std::vector<float> big_vertices{-2, -2, 0, 2, -2, 0, 0, 2, 0};
    const std::vector<uint32_t> big_triangles{0, 1, 2};
    const std::vector<canopy::MeshArrays> meshes{arrays(surface), {big_vertices, big_triangles}};
    const std::vector<canopy::MeshInstance> instances{
        {0, {0.5f, 0, 0, -1, 0, 0.5f, 0, 0, 0, 0, 0.5f, 0}},
        {1, {1, 0, 0, 0, 0, 0, -1, -1.2f, 0, 1, 0, 0}},  // the triangle laid flat below, rotated about x
        {0, {0, -0.4f, 0, 1, 0.4f, 0, 0, 0, 0, 0, 0.4f, 0.5f}}};
    // The same world by hand: each instance's triangles transformed, in instance order.
    std::vector<float> world;
    std::vector<uint32_t> first{0};
    for (const canopy::MeshInstance& instance : instances) {
        const canopy::MeshArrays& mesh = meshes[instance.mesh];
        for (uint32_t index : mesh.triangles)
            for (int row = 0; row < 3; ++row) {
                const float* m = &instance.transform[4 * row];
                const float* p = &mesh.vertices[3 * index];
                world.push_back(m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3]);
            }
        first.push_back(first.back() + uint32_t(mesh.triangles.size() / 3));
    }
    std::vector<uint32_t> world_triangles(world.size() / 3);
    for (uint32_t i = 0; i < world_triangles.size(); ++i) world_triangles[i] = i;
    const Rays rays = random_rays(4000, 3);
    const std::vector<canopy::RayHit> flat = batch_hits(canopy::Accel({world, world_triangles}, {.builder = "binned"}), rays);
    for (const std::string toplevel : {"flat", "two-level", "rebraid"}) {
        INFO(toplevel);
        const canopy::Accel accel(meshes, instances, {.builder = "binned", .toplevel = toplevel});
        const std::vector<canopy::RayHit> hits = batch_hits(accel, rays);
        std::array<size_t, 3> per_instance{};
        for (size_t i = 0; i < rays.count(); ++i) {
            REQUIRE(hits[i].found() == flat[i].found());
            if (!flat[i].found()) continue;
            // Two-level trees intersect in object space: other roundings, which matter near the origins.
            REQUIRE(hits[i].t == Approx(flat[i].t).epsilon(1e-5).margin(1e-5));
            REQUIRE(first[hits[i].instance] + hits[i].triangle == flat[i].triangle);
            ++per_instance.at(hits[i].instance);
        }
        for (size_t hit_count : per_instance) REQUIRE(hit_count > 20);
    }
}

TEST_CASE("api: stats name the builder auto chose, and EPO only when asked", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=2000");
    REQUIRE(canopy::Accel(arrays(mesh)).stats().builder == "binned");  // the plain build by default
    const canopy::AccelStats chosen = canopy::Accel(arrays(mesh), {.builder = "auto"}).stats();
    // "rebraid/binned", "bittner<lbvh": a top level before the builder, an optimiser's start tree after it.
    const size_t slash = chosen.builder.find('/');
    const std::string builder = chosen.builder.substr(slash == std::string::npos ? 0 : slash + 1);
    bool registered = false;
    for (const canopy::BuilderDescription& b : canopy::registered_builders()) registered |= b.name == builder.substr(0, builder.find('<'));
    REQUIRE(registered);
    REQUIRE(!chosen.reason.empty());
    REQUIRE(chosen.triangles == 2000);
    const canopy::Accel binned(arrays(mesh), {.builder = "binned", .kernel = "bvh4"});
    REQUIRE(binned.stats().kernel == "bvh4");
    REQUIRE(!binned.stats().epo);
    const canopy::AccelStats full = binned.stats(true);
    REQUIRE(*full.epo > 0);
    REQUIRE(*full.sah > 0);
    REQUIRE(*full.nodes > 0);
    REQUIRE(full.bytes > 0);
}

TEST_CASE("api: an empty batch does nothing, and hit views may be left out", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=100");
    const canopy::Accel accel(arrays(mesh), {.builder = "lbvh"});
    accel.intersect(canopy::RayBatch{}, canopy::HitBatch{});
    const std::vector<float> origin{0, 0, 5}, down{0, 0, -1};
    std::vector<float> t(1);
    accel.intersect({origin, down, {}, {}}, {.t = t});
    REQUIRE(t[0] == accel.intersect({0, 0, 5}, {0, 0, -1}).t);
    REQUIRE(std::isfinite(t[0]));
}

TEST_CASE("api: bad input throws std::invalid_argument naming the argument", "[api]") {
    const std::vector<float> vertices{0, 0, 0, 1, 0, 0, 0, 1, 0};
    const std::vector<uint32_t> triangles{0, 1, 2};
    const auto build = [&](std::vector<float> v, std::vector<uint32_t> t, canopy::AccelOptions o = {}) {
        return canopy::Accel({v, t}, o);
    };
    using Catch::Contains;
    REQUIRE_THROWS_WITH(build({}, triangles), Contains("vertices: empty"));
    REQUIRE_THROWS_WITH(build({0, 0, 0, 1}, triangles), Contains("vertices: 4 values, not a multiple of 3"));
    REQUIRE_THROWS_WITH(build({0, 0, 0, 1, NAN, 0, 0, 1, 0}, triangles), Contains("vertices[1]: y is nan"));
    REQUIRE_THROWS_WITH(build(vertices, {}), Contains("triangles: empty"));
    REQUIRE_THROWS_WITH(build(vertices, {0, 1}), Contains("triangles: 2 indices"));
    REQUIRE_THROWS_WITH(build(vertices, {0, 1, 2, 2, 1, 3}), Contains("triangles[1]: vertex index 3 is out of range (3 vertices)"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "nosuch"}), Contains("builder: unknown builder 'nosuch'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.kernel = "bvh16"}), Contains("kernel: unknown kernel 'bvh16'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "binned", .toplevel = "x"}), Contains("toplevel: unknown 'x'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.threads = -2}), Contains("threads: -2"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "binned", .layout = "tiny"}), Contains("layout: unknown layout 'tiny'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "auto", .layout = "compressed"}), Contains("layout: compressed nodes take a named BVH builder, kernel bvh8 and a flat top level, not builder 'auto'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "lbvh", .collapse = "zigzag"}), Contains("collapse: unknown collapse 'zigzag'"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "binned", .layout = "compressed", .collapse = "direct"}),
                        Contains("collapse: collapse 'direct' is lbvh's wide tree"));
    REQUIRE_THROWS_WITH(build(vertices, triangles, {.builder = "lbvh", .kernel = "bvh2", .collapse = "direct"}),
                        Contains("collapse: collapse 'direct' is lbvh's wide tree"));

    const std::vector<canopy::MeshArrays> meshes{{vertices, triangles}};
    REQUIRE_THROWS_WITH(canopy::Accel(meshes, std::vector<canopy::MeshInstance>{{1}}), Contains("instances[0].mesh: 1 is out of range (1 meshes)"));
    REQUIRE_THROWS_WITH(canopy::Accel(meshes, std::vector<canopy::MeshInstance>{{0}, {0, {}}}), Contains("instances[1].transform: singular"));
    REQUIRE_THROWS_WITH(canopy::Accel(std::span<const canopy::MeshArrays>{}, {}), Contains("meshes: empty"));
    const std::vector<canopy::MeshArrays> second_bad{{vertices, triangles}, {vertices, {}}};
    REQUIRE_THROWS_WITH(canopy::Accel(second_bad, {}), Contains("meshes[1].triangles: empty"));

    const canopy::Accel accel({vertices, triangles}, {.builder = "binned"});
    const std::vector<float> two{0, 0, 1, 0.2f, 0.2f, 1}, down{0, 0, -1, 0, 0, -1}, nan_origin{0, 0, 1, NAN, 0, 1};
    std::vector<float> t(2);
    std::unique_ptr<bool[]> occluded(new bool[2]);
    REQUIRE_THROWS_WITH(accel.intersect({two, std::span(down).first(3), {}, {}}, {.t = t}), Contains("directions: 1 rays, origins 2"));
    REQUIRE_THROWS_WITH(accel.intersect({std::span(two).first(4), down, {}, {}}, {}), Contains("origins: 4 values"));
    REQUIRE_THROWS_WITH(accel.intersect({nan_origin, down, {}, {}}, {.t = t}), Contains("origins[1]: x is nan"));
    const std::vector<float> three{1, 1, 1}, nan_end{NAN};
    REQUIRE_THROWS_WITH(accel.intersect({two, down, three, {}}, {.t = t}), Contains("tmin: 3 values for 2 rays"));
    REQUIRE_THROWS_WITH(accel.occluded({two, down, {}, nan_end}, {occluded.get(), 2}), Contains("tmax: nan"));
    REQUIRE_THROWS_WITH(accel.occluded({two, down, {}, {}}, {occluded.get(), 1}), Contains("occluded: 1 values for 2 rays"));
    REQUIRE_THROWS_WITH(accel.intersect({two, down, {}, {}}, {.u = std::span(t).first(1)}), Contains("hits.u: 1 values for 2 rays"));
    REQUIRE_THROWS_WITH(accel.intersect({0, 0, 1}, {0, INFINITY, -1}), Contains("directions[0]: y is inf"));
    REQUIRE_THROWS_WITH(accel.occluded({0, 0, 1}, {0, 0, -1}, NAN), Contains("tmin: nan"));
    REQUIRE_THROWS_WITH(accel.occluded({0, 0, 1}, {0, 0, -1}, -1.0f), Contains("tmin: -1.000000 is negative"));
    const std::vector<float> points{0, 0, 0, NAN, 0, 0};
    std::vector<float> distance(2);
    REQUIRE_THROWS_WITH(accel.closest_points(points, {.distance = distance}), Contains("points[1]: x is nan"));
    REQUIRE_THROWS_WITH(accel.closest_points(std::span(points).first(4), {}), Contains("points: 4 values"));
    REQUIRE_THROWS_WITH(canopy::load_triangles("no-such-file.obj"), Contains("no-such-file.obj"));
}

TEST_CASE("api: a ray with a non-finite value misses when the batch asks for it, the others hit as alone", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=500");
    const canopy::Accel accel(arrays(mesh));
    const std::vector<float> origins{0, 0, 0, NAN, 0, 0, 0, 0, 0}, directions{1, 0.1f, 0.2f, 1, 0, 0, -1, 0.3f, 0.1f};
    std::vector<float> t(3);
    std::vector<uint32_t> triangle(3);
    canopy::RayBatch batch{origins, directions, {}, {}, true};
    accel.intersect(batch, {.t = t, .triangle = triangle});
    REQUIRE(triangle[1] == canopy::kNoHit);
    REQUIRE(std::isinf(t[1]));
    REQUIRE(t[0] == accel.intersect({0, 0, 0}, {1, 0.1f, 0.2f}).t);
    REQUIRE(t[2] == accel.intersect({0, 0, 0}, {-1, 0.3f, 0.1f}).t);
    REQUIRE(triangle[0] != canopy::kNoHit);
    batch.invalid_rays_miss = false;
    REQUIRE_THROWS_WITH(accel.intersect(batch, {.t = t}), Catch::Contains("origins[1]: x is nan"));
}

TEST_CASE("api: t is precise on short hits at any scale, and a surface through the origin is not hit", "[api][extreme]") {
    // One big tilted triangle; origins at relative distances 1e-7 to 1e-1 of its size above random points of it.
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (const float scale : {1e-3f, 1.0f, 1e4f}) {
        const std::vector<float> vertices{-1 * scale, -1 * scale, 0.3f * scale, 2 * scale, -0.5f * scale, -0.2f * scale, 0, 2 * scale, 0.1f * scale};
        const std::vector<uint32_t> triangles{0, 1, 2};
        const canopy::Accel accel({vertices, triangles});
        double worst = 0;
        for (int i = 0; i < 2000; ++i) {
            const double a = 0.1 + unit(rng) * 0.3, b = 0.1 + unit(rng) * 0.3, height = std::pow(10.0, -7.0 + 6.0 * unit(rng)) * scale;
            const auto corner = [&](int k, int axis) { return double(vertices[3 * k + axis]); };
            std::array<double, 3> target, normal;
            for (int axis = 0; axis < 3; ++axis)
                target[axis] = corner(0, axis) + a * (corner(1, axis) - corner(0, axis)) + b * (corner(2, axis) - corner(0, axis));
            const auto edge = [&](int k, int axis) { return corner(k, axis) - corner(0, axis); };
            normal = {edge(1, 1) * edge(2, 2) - edge(1, 2) * edge(2, 1), edge(1, 2) * edge(2, 0) - edge(1, 0) * edge(2, 2),
                      edge(1, 0) * edge(2, 1) - edge(1, 1) * edge(2, 0)};
            const double length = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
            const std::array<float, 3> origin{float(target[0] + height * normal[0] / length), float(target[1] + height * normal[1] / length),
                                              float(target[2] + height * normal[2] / length)};
            const std::array<float, 3> direction{float(-normal[0] / length + 0.1 * (unit(rng) - 0.5)), float(-normal[1] / length),
                                                 float(-normal[2] / length)};
            const canopy::RayHit hit = accel.intersect(origin, direction);
            REQUIRE(hit.found());
            // The exact distance from the float origin and direction, in long double.
            long double n_dot_d = 0, n_dot_w = 0;
            for (int axis = 0; axis < 3; ++axis) {
                const long double n = (long double)(edge(1, (axis + 1) % 3)) * edge(2, (axis + 2) % 3) -
                                      (long double)(edge(1, (axis + 2) % 3)) * edge(2, (axis + 1) % 3);
                n_dot_d += n * direction[axis];
                n_dot_w += n * ((long double)(corner(0, axis)) - origin[axis]);
            }
            const long double exact = n_dot_w / n_dot_d;
            worst = std::max(worst, double(std::abs((hit.t - exact) / exact)));
        }
        INFO("scale " << scale);
        CHECK(worst <= 2.0 * 0x1p-24);  // the float rounding of the exact distance, and the inputs' exactness
    }
    // Origins exactly on surfaces: every corner and edge midpoint of a closed cube's triangles, rays both ways.
    const canopy::Accel cube(arrays(kCube));
    size_t hits = 0;
    for (size_t k = 0; k < kCube.triangles.size(); ++k) {
        const float* v0 = &kCube.vertices[3 * kCube.triangles[k]];
        const float* v1 = &kCube.vertices[3 * kCube.triangles[k % 3 == 2 ? k - 2 : k + 1]];
        const std::array<float, 3> corner{v0[0], v0[1], v0[2]}, midpoint{0.5f * (v0[0] + v1[0]), 0.5f * (v0[1] + v1[1]), 0.5f * (v0[2] + v1[2])};
        for (const std::array<float, 3>& origin : {corner, midpoint})
            for (const float sign : {1.0f, -1.0f}) {
                const canopy::RayHit hit = cube.intersect(origin, {sign * (0.3f - origin[0]), sign * (0.2f - origin[1]), sign * (0.1f - origin[2])});
                REQUIRE((!hit.found() || hit.t > 0.5f));  // the far side of the cube, never the surface at the origin
                hits += hit.found();
            }
    }
    CHECK(hits >= kCube.triangles.size());
}

TEST_CASE("api: every hit along a ray, in order, each triangle once, the closest hit first", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=3000&seed=4");
    for (const char* kernel : {"bvh2", "bvh4", "bvh8"}) {
        const canopy::Accel accel(arrays(mesh), {.kernel = kernel});
        const Rays rays = random_rays(20000, 5);  // many chunks of a batch
        canopy::HitList list;
        accel.intersect_all(rays.batch(), list);
        std::vector<uint32_t> counts(rays.count());
        accel.count_hits(rays.batch(), counts);
        const std::vector<canopy::RayHit> closest = batch_hits(accel, rays);
        REQUIRE(list.offsets.size() == rays.count() + 1);
        size_t several = 0;
        for (size_t i = 0; i < rays.count(); ++i) {
            const size_t first = list.offsets[i], end = list.offsets[i + 1];
            REQUIRE(counts[i] == end - first);
            REQUIRE(closest[i].found() == (end > first));
            if (end == first) continue;
            REQUIRE(list.t[first] == closest[i].t);
            std::vector<uint32_t> seen;
            for (size_t k = first; k < end; ++k) {
                if (k > first) REQUIRE(list.t[k] >= list.t[k - 1]);
                seen.push_back(list.triangle[k]);
            }
            std::sort(seen.begin(), seen.end());
            REQUIRE(std::adjacent_find(seen.begin(), seen.end()) == seen.end());
            several += end - first > 1;
        }
        CHECK(several > rays.count() / 10);
    }
}

TEST_CASE("api: closest points and inside tests on a closed box match its distance function", "[api]") {
    for (const char* kernel : {"bvh2", "bvh4", "bvh8"}) {
        const canopy::Accel accel(arrays(kCube), {.kernel = kernel});
        std::mt19937 rng(9);
        std::uniform_real_distribution<float> uniform(-3.0f, 3.0f);
        std::vector<float> points(3 * 5000);
        for (float& x : points) x = uniform(rng);
        const size_t n = points.size() / 3;
        std::vector<float> nearest(3 * n), distance(n);
        std::vector<uint32_t> triangle(n);
        std::unique_ptr<bool[]> inside(new bool[n]);
        accel.closest_points(points, {.point = nearest, .distance = distance, .triangle = triangle});
        accel.contains(points, {inside.get(), n});
        for (size_t i = 0; i < n; ++i) {
            const float x = points[3 * i], y = points[3 * i + 1], z = points[3 * i + 2];
            const float outside = std::hypot(std::max(std::abs(x) - 1, 0.0f), std::max(std::abs(y) - 1, 0.0f), std::max(std::abs(z) - 1, 0.0f));
            const bool in = std::max({std::abs(x), std::abs(y), std::abs(z)}) < 1;
            const float expected = in ? 1 - std::max({std::abs(x), std::abs(y), std::abs(z)}) : outside;
            INFO(kernel << " point " << x << " " << y << " " << z);
            REQUIRE(std::abs(distance[i] - expected) <= 1e-6f);
            REQUIRE(inside[i] == in);
            REQUIRE(triangle[i] < 12);
            REQUIRE(std::max({std::abs(nearest[3 * i]), std::abs(nearest[3 * i + 1]), std::abs(nearest[3 * i + 2])}) == Approx(1.0f));
        }
    }
}

TEST_CASE("api: ray lists and point queries need a flat tree of standard nodes", "[api]") {
    const canopy::TriangleMesh mesh = canopy::load_triangles("gen:box?tris=100");
    const std::vector<canopy::MeshArrays> meshes{arrays(mesh)};
    const canopy::Accel two_level(meshes, {}, {.toplevel = "two-level"});
    const std::vector<float> point{0, 0, 0};
    std::vector<float> distance(1);
    REQUIRE_THROWS_WITH(two_level.closest_points(point, {.distance = distance}), Catch::Contains("closest_points: needs a flat tree"));
    canopy::HitList list;
    REQUIRE_THROWS_WITH(two_level.intersect_all({point, point, {}, {}}, list), Catch::Contains("intersect_all: needs a flat tree"));
}
