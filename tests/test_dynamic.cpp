// Dynamic-in-static scenes (Benthin et al. 2017, sec. 6.3): after the object moves, every top level and Embree
// trace the moved world triangles as brute force does, frame images show it where its placement puts it, the
// motion is deterministic, rigid, closed and inside the scene, and --dynamic names itself when it is wrong.
#include "experiments/dynamic.h"
#include "experiments/embree_accelerator.h"
#include "two_level_support.h"

#include <glm/gtc/matrix_inverse.hpp>

#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

// A room with a few shapes on its floor, in which auto moves one shape.
Scene room_scene() { return load_scene("gen:box?tris=6000&seed=3"); }

// Every accelerator the dynamic bench can run, over `flat`, which the test moves the object in.
std::vector<std::unique_ptr<Accelerator>> all_accelerators(const Scene& scene, const FlatScene& flat) {
    std::vector<std::unique_ptr<Accelerator>> all;
    for (const char* top : {"flat", "two-level", "rebraid"})
        all.push_back(make_canopy_accelerator(scene, flat, {"binned", "", "auto", true, true, top}));
    all.push_back(make_embree_accelerator(flat, "medium", 0));
    all.push_back(make_embree_two_level_accelerator(scene, flat, "medium", 0));
    for (auto& accel : all) accel->prepare(), accel->build();
    return all;
}

std::string name_of(const Accelerator& accel) { return accel.library() + " " + accel.builder() + accel.quality(); }

// Rays from random points around the object towards random points on its moved triangles, so the test sees it.
std::vector<Ray> rays_at(const FlatScene& flat, const DynamicObject& object, size_t count, uint64_t seed) {
    const std::span<const Triangle> moved(flat.triangles.data() + object.first_triangle, object.triangles.size());
    BBox bounds;
    for (const Triangle& t : moved) bounds.extend(BBox::of(t));
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays(count);
    for (Ray& ray : rays) {
        const Vec3 away = glm::normalize(Vec3(unit(rng), unit(rng), unit(rng)) - 0.5f);
        const Triangle& t = moved[rng() % moved.size()];
        const float a = 0.1f + 0.4f * unit(rng), b = 0.1f + 0.4f * unit(rng);  // inside, off the edges
        ray.org = bounds.center() + 2.0f * glm::length(bounds.extent()) * away;
        ray.dir = glm::normalize(t.v0 + a * (t.v1 - t.v0) + b * (t.v2 - t.v0) - ray.org);
    }
    return rays;
}

size_t hits_on(const DynamicObject& object, const std::vector<Hit>& hits) {
    size_t n = 0;
    for (const Hit& h : hits) n += h.found() && h.prim >= object.first_triangle && h.prim < object.first_triangle + object.triangles.size();
    return n;
}

void check_against_brute_force(const Scene& scene, const std::string& spec) {
    FlatScene flat = flatten(scene);
    const DynamicObject object = choose_dynamic_object(scene, flat, spec);
    const auto accelerators = all_accelerators(scene, flat);
    const float touch = 1e-5f * glm::length(flat.bounds.extent());
    for (const uint32_t frame : {1u, 5u, 13u}) {
        const PlacementMove move = move_dynamic_object(object, frame, flat);
        // Rays from one point of a flat face to another lie in its plane; there world and object space round
        // differently, so rays starting on surfaces are left out (the moved object is an instance).
        std::vector<Ray> rays = off_surface(random_rays(flat.triangles, 4000, 90 + frame));
        const std::vector<Ray> aimed = rays_at(flat, object, 1000, 190 + frame);
        rays.insert(rays.end(), aimed.begin(), aimed.end());
        const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
        REQUIRE(hits_on(object, expected) > 250);  // the rays do see the moved object (overlapping copies hide some)
        for (const auto& accel : accelerators) {
            accel->move(move);
            INFO(name_of(*accel) << ", frame " << frame);
            CHECK(disagreements(*accel, rays, expected, touch) <= rays.size() / 1000);
        }
    }
}

// One frame of 48x36 pixels with one bounce, so a moved object changes what primary rays hit and shade.
std::vector<float> frame_image(const auto& tracer, const Scene& scene, const FlatScene& flat, uint32_t frame) {
    FrameSettings settings;
    settings.width = 48, settings.height = 36, settings.max_bounces = 1;
    const ShadingScene shading{flat, settings};
    Image image(settings.width, settings.height);
    render_frame(tracer, shading, PinholeCamera(scene_camera(scene, flat), settings.width, settings.height), frame, image);
    return image.average(1);
}

size_t differing_values(const std::vector<float>& a, const std::vector<float>& b) {
    size_t n = 0;
    for (size_t i = 0; i < a.size(); ++i) n += a[i] != b[i];
    return n;
}

struct AcceleratorTracer {
    const Accelerator& accel;
    bool closest(const Ray& ray, Hit& hit) const {
        hit = accel.trace(ray);
        return hit.found();
    }
};

}  // namespace

TEST_CASE("after a move, every top level and Embree agree with brute force over the moved triangles", "[dynamic]") {
    SECTION("an object of a mesh, in world space at rest") { check_against_brute_force(room_scene(), "auto"); }
    SECTION("an instance rotated and scaled non-uniformly at rest") {
        const Scene scene = instanced_scene();
        check_against_brute_force(scene, std::to_string(scene.meshes[0].objects.size()));  // the first surface instance
    }
}

TEST_CASE("frame images show the moved object where its placement puts it", "[dynamic]") {
    const Scene scene = room_scene();
    FlatScene flat = flatten(scene);
    const DynamicObject object = choose_dynamic_object(scene, flat, "auto");
    const auto accelerators = all_accelerators(scene, flat);
    const std::vector<float> at_rest = frame_image(BruteForceTracer{flat.triangles}, scene, flat, 7);
    const PlacementMove move = move_dynamic_object(object, 7, flat);
    const std::vector<float> expected = frame_image(BruteForceTracer{flat.triangles}, scene, flat, 7);
    CHECK(differing_values(at_rest, expected) > 30);  // the move shows
    for (const auto& accel : accelerators) {
        accel->move(move);
        INFO(name_of(*accel));
        CHECK(differing_values(frame_image(AcceleratorTracer{*accel}, scene, flat, 7), expected) <= 6);  // 2 pixels
    }
}

TEST_CASE("the motion is deterministic, rigid, closed and stays inside the scene", "[dynamic]") {
    const Scene scene = room_scene();
    FlatScene flat = flatten(scene);
    const BBox scene_bounds = flat.bounds;
    const DynamicObject object = choose_dynamic_object(scene, flat, "auto");
    REQUIRE(object.path_radius > 0.1f);
    CHECK(dynamic_placement(object, 0) == object.rest);
    CHECK(dynamic_placement(object, kFramesPerTurn) == object.rest);
    const float tolerance = 1e-5f * glm::length(scene_bounds.extent());
    BBox rest;
    for (size_t i = 0; i < object.triangles.size(); ++i) rest.extend(BBox::of(flat.triangles[object.first_triangle + i]));
    const Vec3 rest_centre = rest.center();
    for (uint32_t frame = 0; frame < kFramesPerTurn; ++frame) {
        const glm::mat4 m = dynamic_placement(object, frame);
        const glm::mat4 again = dynamic_placement(choose_dynamic_object(scene, flatten(scene), "auto"), frame);
        CHECK(std::memcmp(&m, &again, sizeof m) == 0);
        const glm::mat3 turn(m * glm::inverse(object.rest));
        const glm::mat3 gram = glm::transpose(turn) * turn;  // the identity for a rotation: no scale, no shear
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) CHECK(gram[i][j] == Approx(i == j ? 1.0f : 0.0f).margin(1e-5));
        CHECK(glm::determinant(turn) == Approx(1.0f).margin(1e-5));
        place_dynamic_object(object, m, flat);
        BBox moved;
        for (size_t i = 0; i < object.triangles.size(); ++i) moved.extend(BBox::of(flat.triangles[object.first_triangle + i]));
        CHECK(glm::all(glm::greaterThanEqual(moved.lower, scene_bounds.lower - tolerance)));
        CHECK(glm::all(glm::lessThanEqual(moved.upper, scene_bounds.upper + tolerance)));
        if (frame == kFramesPerTurn / 2)  // half a turn: the centre is across the circle from where it was
            CHECK(glm::distance(moved.center(), rest_centre) == Approx(2.0f * object.path_radius).margin(tolerance));
    }
}

TEST_CASE("The --dynamic option chooses by auto, index or name, in two_level_input's numbering, and names itself when wrong",
          "[dynamic]") {
    Scene scene = room_scene();
    const FlatScene flat = flatten(scene);
    const TwoLevelInput input = two_level_input(scene);
    const DynamicObject automatic = choose_dynamic_object(scene, flat, "auto");
    CHECK((automatic.name.starts_with("sphere_") || automatic.name.starts_with("box_")));  // a shape, not a wall
    const TwoLevelInstance& placed = input.instances.at(automatic.placement);
    CHECK(placed.prim_offset == automatic.first_triangle);
    CHECK(input.objects[placed.object].size() == automatic.triangles.size());
    CHECK(choose_dynamic_object(scene, flat, "2").placement == 2);
    CHECK(choose_dynamic_object(scene, flat, "back_wall").name == "back_wall");
    CHECK(choose_dynamic_object(scene, flat, automatic.name).placement == automatic.placement);
    using Catch::Matchers::Contains;
    CHECK_THROWS_WITH(choose_dynamic_object(scene, flat, "nosuch"), Contains("--dynamic 'nosuch'"));
    CHECK_THROWS_WITH(choose_dynamic_object(scene, flat, ""), Contains("--dynamic ''"));
    CHECK_THROWS_WITH(choose_dynamic_object(scene, flat, std::to_string(input.instances.size())), Contains("--dynamic"));
    CHECK_THROWS_WITH(choose_dynamic_object(scene, flat, "99999999999999999999"), Contains("--dynamic"));
    Mesh& mesh = scene.meshes[0];
    mesh.objects.insert(mesh.objects.begin(), Object{"nothing", 0, 0});
    CHECK_THROWS_WITH(choose_dynamic_object(scene, flatten(scene), "nothing"), Contains("no triangles"));
}
