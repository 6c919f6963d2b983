// Procedural scenes: exact counts, determinism, framing, shape character, spec errors.
#include "scenes_test_support.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>

using namespace canopy;
using canopy::test::input_error_of;
using Catch::Matchers::Contains;

namespace {

const char* const generators[] = {"box", "city", "cylinders", "foliage", "mirror", "room", "surface", "triangles"};

std::string spec(const std::string& generator, uint64_t tris, uint64_t seed) {
    return "gen:" + generator + "?tris=" + std::to_string(tris) + "&seed=" + std::to_string(seed);
}

uint64_t triangle_count(const std::string& spec) { return instanced_triangle_count(generate_scene(spec)); }

// Median over triangles of (bounding box surface) / (triangle area): large for long thin
// slanted triangles, where spatial splits pay; under about 10 for compact ones.
double median_box_to_area_ratio(const Scene& scene) {
    std::vector<double> ratios;
    for (const Triangle& t : flatten(scene).triangles) {
        const double area = triangle_area(t);
        if (area > 0) ratios.push_back(BBox::of(t).area() / area);
    }
    std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
    return ratios[ratios.size() / 2];
}

// How many triangles use each undirected edge.
std::map<std::pair<uint32_t, uint32_t>, int> edge_uses(const Mesh& mesh) {
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (const glm::uvec3& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = t[k], b = t[(k + 1) % 3];
            ++uses[{std::min(a, b), std::max(a, b)}];
        }
    return uses;
}

}  // namespace

TEST_CASE("generators produce exactly N triangles where the shape allows", "[scenes][generators]") {
    for (uint64_t n : {1000u, 1001u, 12345u, 100000u}) {
        INFO("tris=" << n);
        CHECK(triangle_count(spec("box", n, 1)) == n);
        CHECK(triangle_count(spec("mirror", n, 1)) == n);
        CHECK(triangle_count(spec("triangles", n, 1)) == n);
        CHECK(triangle_count(spec("foliage", n, 1)) == n);
        CHECK(triangle_count(spec("city", n, 1)) == n);
        // Open cylinders and closed surfaces have an even count: an odd N gives N + 1.
        CHECK(triangle_count(spec("cylinders", n, 1)) == n + n % 2);
        CHECK(triangle_count(spec("surface", n, 1)) == n + n % 2);
        CHECK(triangle_count(spec("room", n, 1)) == n + n % 2);
    }
    // Below each shape's minimum, the minimum.
    CHECK(triangle_count("gen:box?tris=1") == 118);
    CHECK(triangle_count("gen:cylinders?tris=1") == 6);
    CHECK(triangle_count("gen:mirror?tris=1") == 144);
    CHECK(triangle_count("gen:surface?tris=1") == 18);
    CHECK(triangle_count("gen:room?tris=1") == 108);
    CHECK(triangle_count("gen:triangles?tris=1") == 1);
    CHECK(triangle_count("gen:foliage?tris=1") == 14);  // the trunk and one leaf
    CHECK(triangle_count("gen:city?tris=1") == 12);     // the ground and one building
    for (uint64_t n : {13u, 14u, 15u, 799u, 800u, 801u}) {
        INFO("tris=" << n);
        CHECK(triangle_count(spec("foliage", n, 2)) == std::max<uint64_t>(n, 14));
        CHECK(triangle_count(spec("city", n, 2)) == n);
    }
    CHECK(triangle_count("gen:box") == 100000);  // the default tris
}

TEST_CASE("generators are deterministic from the seed", "[scenes][generators]") {
    for (const char* generator : generators) {
        INFO(generator);
        const Mesh first = generate_scene(spec(generator, 5000, 7)).meshes[0];
        const Mesh again = generate_scene(spec(generator, 5000, 7)).meshes[0];
        const Mesh other = generate_scene(spec(generator, 5000, 8)).meshes[0];
        CHECK(first.positions == again.positions);
        CHECK(first.triangles == again.triangles);
        CHECK(first.positions != other.positions);
    }
    // The stream and its mapping to floats are canopy's own: these numbers hold on every platform.
    const Mesh one = generate_scene("gen:triangles?tris=1&seed=42").meshes[0];
    REQUIRE(one.positions.size() == 3);
    CHECK(one.positions[0] == Vec3(-0x1.3f18fp-2f, -0x1.d90e9ep-1f, 0x1.7910c8p-1f));
}

TEST_CASE("generated scenes are valid, finite and framed by their camera", "[scenes][generators]") {
    for (const char* generator : generators) {
        INFO(generator);
        const Scene scene = generate_scene(spec(generator, 20000, 3));
        test::check_mesh_invariants(scene);
        CHECK(scene.materials.empty());
        const FlatScene flat = flatten(scene);
        for (const Triangle& t : flat.triangles)
            REQUIRE((std::isfinite(t.v0.x + t.v0.y + t.v0.z + t.v1.x + t.v1.y + t.v1.z + t.v2.x + t.v2.y + t.v2.z)));
        REQUIRE(scene.camera.has_value());
        const Camera& camera = *scene.camera;
        CHECK(test::contains(flat.bounds, camera.target));
        CHECK(glm::length(camera.target - camera.eye) > 0.0f);
        CHECK((camera.fov_deg > 0.0f && camera.fov_deg < 180.0f));
        // It looks into the geometry: the bounds centre is near the middle of the view.
        const Vec3 forward = glm::normalize(camera.target - camera.eye);
        CHECK(glm::dot(forward, glm::normalize(flat.bounds.center() - camera.eye)) > 0.95f);
    }
}

TEST_CASE("gen:box is a room of five walls holding spheres and boxes, each its own object", "[scenes][generators]") {
    const Scene scene = generate_scene("gen:box?tris=30001&seed=2");
    const std::vector<Object>& objects = scene.meshes[0].objects;
    REQUIRE(objects.size() > 7);
    std::vector<std::string> walls;
    for (size_t i = 0; i < 5; ++i) walls.push_back(objects[i].name);
    CHECK(walls == std::vector<std::string>{"floor", "ceiling", "left_wall", "right_wall", "back_wall"});
    CHECK(objects[4].triangle_count == 3);  // the odd triangle
    for (size_t i = 5; i < objects.size(); ++i)
        CHECK((objects[i].name.starts_with("sphere_") || objects[i].name.starts_with("box_")));
}

TEST_CASE("gen:cylinders has long thin triangles, gen:surface compact ones", "[scenes][generators]") {
    const double cylinders = median_box_to_area_ratio(generate_scene("gen:cylinders?tris=20000"));
    const double surface = median_box_to_area_ratio(generate_scene("gen:surface?tris=20000"));
    CHECK(cylinders > 40.0);  // about 95
    CHECK(surface < 12.0);    // about 8, as for a randomly oriented equilateral triangle
    CHECK(generate_scene("gen:cylinders?tris=200000").meshes[0].objects.size() > 1);
}

TEST_CASE("gen:surface is closed: every edge is shared by exactly two triangles", "[scenes][generators]") {
    for (uint64_t n : {1000u, 4321u}) {
        const Mesh mesh = generate_scene(spec("surface", n, 5)).meshes[0];
        const std::map<std::pair<uint32_t, uint32_t>, int> uses = edge_uses(mesh);
        CHECK(std::all_of(uses.begin(), uses.end(), [](const auto& e) { return e.second == 2; }));
    }
}

TEST_CASE("gen:room is a closed scan of compact triangles, seen from inside", "[scenes][generators]") {
    for (uint64_t n : {108u, 5001u, 40000u}) {
        INFO("tris=" << n);
        const Scene scene = generate_scene(spec("room", n, 6));
        // Closed where faces meet too: every edge, by its end points' positions, is shared by exactly two triangles.
        std::map<std::pair<std::array<float, 3>, std::array<float, 3>>, int> uses;
        const auto key = [](const Vec3& p) { return std::array<float, 3>{p.x, p.y, p.z}; };
        const FlatScene flat = flatten(scene);
        for (const Triangle& t : flat.triangles) {
            REQUIRE(triangle_area(t) > 0.0f);
            const Vec3 corners[3] = {t.v0, t.v1, t.v2};
            for (int k = 0; k < 3; ++k) ++uses[std::minmax(key(corners[k]), key(corners[(k + 1) % 3]))];
        }
        CHECK(std::all_of(uses.begin(), uses.end(), [](const auto& e) { return e.second == 2; }));
        // Seen from inside: the eye within the bounds, and the scene's statistics say so.
        const Vec3 eye = scene.camera->eye;
        CHECK(glm::all(glm::greaterThan(eye, flat.bounds.lower)));
        CHECK(glm::all(glm::lessThan(eye, flat.bounds.upper)));
    }
    // Compact triangles, as a scan's (gen:surface's about 8), not slivers.
    CHECK(median_box_to_area_ratio(generate_scene("gen:room?tris=20000")) < 12.0);
    // The walls bulge and carry noise: not a box of flat faces.
    const FlatScene flat = flatten(generate_scene("gen:room?tris=20000&seed=2"));
    std::set<float> heights;
    for (const Triangle& t : flat.triangles)
        if (glm::normalize(geometric_normal(t)).y > 0.99f) heights.insert(t.v0.y);
    CHECK(heights.size() > 100);
}

TEST_CASE("gen:mirror is one crack-free surface, open only at its hole and flange", "[scenes][generators]") {
    for (uint64_t n : {1u, 1001u, 12347u, 85651u}) {  // the minimum; rim cells of 0 to 2 extra triangles
        INFO("tris=" << n);
        const Scene scene = generate_scene(spec("mirror", n, 3));
        const Mesh& mesh = scene.meshes[0];
        REQUIRE(mesh.objects.size() == 2);
        CHECK(mesh.objects[0].name == "mirror");
        CHECK(mesh.objects[1].name == "rim");
        std::set<std::pair<uint32_t, uint32_t>> directed;
        for (const glm::uvec3& t : mesh.triangles)
            for (int k = 0; k < 3; ++k) REQUIRE(directed.insert({t[k], t[(k + 1) % 3]}).second);  // wound alike
        for (const auto& [edge, uses] : edge_uses(mesh)) {
            if (uses == 2) continue;
            REQUIRE(uses == 1);  // a boundary edge: both ends on the hole (r 0.2) or both on the flange (r 1.15)
            const auto at_radius = [&](uint32_t vertex, float r) {
                return std::abs(glm::length(glm::vec2(mesh.positions[vertex])) - r) < 1e-5f;
            };
            CHECK(((at_radius(edge.first, 0.2f) && at_radius(edge.second, 0.2f)) ||
                   (at_radius(edge.first, 1.15f) && at_radius(edge.second, 1.15f))));
        }
        for (const Triangle& t : flatten(scene).triangles) REQUIRE(triangle_area(t) > 0.0f);
    }
}

TEST_CASE("gen:mirror's slivers are thinner in its coarse tessellation than in its fine one", "[scenes][generators]") {
    const double coarse = median_box_to_area_ratio(generate_scene("gen:mirror?tris=20000"));
    const double fine = median_box_to_area_ratio(generate_scene("gen:mirror?tris=80000"));
    CHECK(coarse > 200.0);       // about 350: 4 rings of 1824 sectors
    CHECK(fine < 0.6 * coarse);  // about 150: 15 rings of 2400 sectors
}

TEST_CASE("default_scene is a small embedded scene that load_scene(\"\") returns", "[scenes][generators]") {
    const Scene scene = load_scene("");
    const uint64_t count = instanced_triangle_count(scene);
    CHECK((count >= 20000 && count <= 50000));
    CHECK(scene.camera.has_value());
    CHECK(count == instanced_triangle_count(default_scene()));
}

TEST_CASE("bad generator specs name the spec and the key", "[scenes][generators][errors]") {
    struct Case {
        std::string spec;
        const char* detail;
    };
    const Case cases[] = {
        {"gen:teapot", "'teapot'"},
        {"gen:", "unknown generator"},
        {"gen:box?tris=abc", "tris"},
        {"gen:box?tris=0", "tris"},
        {"gen:box?tris=-5", "tris"},
        {"gen:box?tris=12x", "tris"},
        {"gen:box?tris=999999999999", "tris"},
        {"gen:box?seed=", "seed"},
        {"gen:box?seed=1.5", "seed"},
        {"gen:box?size=3", "'size'"},
        {"gen:box?tris=5&tris=6", "twice"},
        {"gen:box?tris", "'tris'"},
        {"gen:box?", "key=value"},
        {"gen:surface?tris=100&", "key=value"},
    };
    for (const Case& c : cases) {
        INFO(c.spec);
        CHECK_THAT(input_error_of([&] { load_scene(c.spec); }), Contains(c.spec) && Contains(c.detail));
    }
}

TEST_CASE("gen:foliage is thin leaves at every orientation around a trunk and branches", "[scenes][generators]") {
    const Scene scene = generate_scene("gen:foliage?tris=48000&seed=4");
    const std::vector<Object>& objects = scene.meshes[0].objects;
    REQUIRE(objects.size() > 2);
    CHECK(objects[0].name == "branches");
    CHECK(objects[0].triangle_count == 120 * 12);  // a branch a 400 triangles, 12 each
    for (size_t i = 1; i < objects.size(); ++i) CHECK(objects[i].name == "leaves_" + std::to_string(i - 1));
    // Slivers: a leaf's box is mostly empty (cylinders' are about 95, compact surfaces' under 10).
    CHECK(median_box_to_area_ratio(scene) > 15.0);
    // Leaves face every way: normals spread over all three axes.
    Vec3 mean_abs_normal(0.0f);
    const FlatScene flat = flatten(scene);
    for (const Triangle& t : flat.triangles) mean_abs_normal += glm::abs(glm::normalize(glm::cross(t.v1 - t.v0, t.v2 - t.v0)));
    mean_abs_normal /= float(flat.triangles.size());
    for (int a = 0; a < 3; ++a) CHECK((mean_abs_normal[a] > 0.35f && mean_abs_normal[a] < 0.65f));
}

TEST_CASE("gen:city is axis-aligned buildings of widely varied sizes, seen from street level", "[scenes][generators]") {
    const Scene scene = generate_scene("gen:city?tris=20001&seed=5");
    const std::vector<Object>& objects = scene.meshes[0].objects;
    REQUIRE(objects.size() > 3);
    CHECK(objects.front().name == "ground");
    CHECK(objects.back().name == "markings");
    CHECK((objects.back().triangle_count > 0 && objects.back().triangle_count < 20001 / 16));  // the remainder
    const FlatScene flat = flatten(scene);
    float lowest_top = 1.0f, highest_top = 0.0f;
    for (const Triangle& t : flat.triangles) {
        const Vec3 n = glm::cross(t.v1 - t.v0, t.v2 - t.v0);
        REQUIRE(int(n.x == 0.0f) + int(n.y == 0.0f) + int(n.z == 0.0f) == 2);  // every face axis-aligned
        const bool roof = n.x == 0.0f && n.z == 0.0f && t.v0.y > 0.01f;  // not the ground or a marking
        if (roof) lowest_top = std::min(lowest_top, t.v0.y), highest_top = std::max(highest_top, t.v0.y);
    }
    CHECK(highest_top > 10.0f * lowest_top);
    // The eye stands in a street, below every roof.
    const Camera& camera = *scene.camera;
    CHECK(camera.eye.y < lowest_top);
    CHECK(std::abs(camera.eye.x) < 0.01f);
}
