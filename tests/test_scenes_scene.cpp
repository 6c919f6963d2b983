// load_scene dispatch, flatten and auto_camera.
#include "scenes_test_support.h"

#include <sys/stat.h>

#include <cmath>

using namespace canopy;
using canopy::test::input_error_of;
using canopy::test::TempDir;
using Catch::Matchers::Contains;

namespace {

Mesh unit_triangle_mesh() {
    Mesh mesh;
    mesh.name = "tri";
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    mesh.triangles = {{0, 1, 2}};
    mesh.objects = {{"tri", 0, 1}};
    return mesh;
}

glm::mat4 translation(const Vec3& t) {
    glm::mat4 m(1.0f);
    m[3] = glm::vec4(t, 1.0f);
    return m;
}

}  // namespace

TEST_CASE("load_scene dispatches on the name and rejects what it cannot load", "[scenes][dispatch]") {
    TempDir dir;
    const std::string obj = dir.write("tri.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    CHECK(instanced_triangle_count(load_scene(obj)) == 1);
    dir.write("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    const std::string json = dir.write("s.json", R"({"meshes": [{"name": "t", "file": "tri.obj"}]})");
    CHECK(load_scene(json).meshes[0].name == "t");
    CHECK(instanced_triangle_count(load_scene("gen:surface?tris=100")) == 100);
    CHECK(load_scene("").name == "default");

    CHECK_THAT(input_error_of([&] { load_scene(dir.write("notes.txt", "hello")); }), Contains("notes.txt"));
    CHECK_THAT(input_error_of([] { load_scene("no-extension"); }), Contains("no-extension"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("absent.obj")); }), Contains("absent.obj"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("absent.json")); }), Contains("absent.json"));
}

TEST_CASE("a folder or a FIFO given as a scene or a mesh is named as what it is", "[scenes][dispatch][errors]") {
    TempDir dir;
    std::filesystem::create_directory(dir.file("folder.obj"));
    std::filesystem::create_directory(dir.file("folder.json"));
    REQUIRE(mkfifo(dir.file("fifo.gltf").c_str(), 0600) == 0);
    REQUIRE(mkfifo(dir.file("fifo.obj").c_str(), 0600) == 0);
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("folder.obj")); }),
               Contains("folder.obj: is a folder, not a file"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("folder.json")); }),
               Contains("folder.json: is a folder, not a file"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("fifo.gltf")); }),
               Contains("fifo.gltf: is not a regular file (a FIFO, socket or device)"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.file("absent.gltf")); }), Contains("absent.gltf: no such file"));
    const std::string json = dir.write("scene.json", R"({"meshes": [{"name": "f", "file": "fifo.obj"}]})");
    CHECK_THAT(input_error_of([&] { load_scene(json); }),
               Contains("scene.json: meshes[0].file: ") && Contains("fifo.obj: is not a regular file"));
}

TEST_CASE("load_scene warns, once, when every triangle has zero area", "[scenes][dispatch]") {
    TempDir dir;
    const std::string line = "v 0 0 0\nv 1 0 0\nv 2 0 0\n";
    const std::string flat = dir.write("flat.obj", line + "f 1 2 3\nf 1 1 2\n");  // collinear, coincident
    const std::string json = dir.write("twice.json", R"({"meshes": [{"name": "f", "file": "flat.obj"}],
        "instances": [{"mesh": "f"}, {"mesh": "f", "transform": [1,0,0,0, 0,1,0,5, 0,0,1,0, 0,0,0,1]}]})");
    const std::string mixed = dir.write("mixed.obj", line + "v 0 1 0\nf 1 2 3\nf 1 2 4\n");
    {
        test::CaptureStderr stderr_capture;
        CHECK(instanced_triangle_count(load_scene(flat)) == 2);
        CHECK(stderr_capture.text() ==
              "canopy: warning: '" + flat + "': all 2 triangles have zero area; no ray can hit them\n");
    }
    {
        test::CaptureStderr stderr_capture;
        load_scene(json);
        CHECK_THAT(stderr_capture.text(), Contains("twice.json': all 4 triangles have zero area"));
    }
    test::CaptureStderr stderr_capture;
    load_scene(mixed);
    CHECK(stderr_capture.text().empty());
}

TEST_CASE("flatten transforms every instance's triangles, in instance order", "[scenes][flatten]") {
    Scene scene;
    scene.meshes.push_back(unit_triangle_mesh());
    scene.instances = {{0, glm::mat4(1.0f)}, {0, translation({5, 0, 0})}};
    const FlatScene flat = flatten(scene);
    REQUIRE(flat.triangles.size() == 2);
    CHECK(flat.triangles[0].v1 == Vec3(1, 0, 0));
    CHECK(flat.triangles[1].v1 == Vec3(6, 0, 0));
    CHECK(flat.bounds.lower == Vec3(0, 0, 0));
    CHECK(flat.bounds.upper == Vec3(6, 1, 0));
    CHECK(flat.material.empty());
    CHECK(flat.materials.empty());
    CHECK(instanced_triangle_count(scene) == 2);
}

TEST_CASE("flatten carries materials, with a default for meshes that have none", "[scenes][flatten]") {
    Scene scene;
    Mesh coloured = unit_triangle_mesh();
    coloured.triangle_material = {1};
    scene.meshes = {coloured, unit_triangle_mesh()};
    scene.materials = {{"white", Vec3(1)}, {"red", Vec3(1, 0, 0)}};
    scene.instances = {{1, glm::mat4(1.0f)}, {0, glm::mat4(1.0f)}, {1, glm::mat4(1.0f)}};
    const FlatScene flat = flatten(scene);
    REQUIRE(flat.materials.size() == 3);
    CHECK(flat.materials[2].kd == Vec3(0.8f));
    CHECK(flat.material == std::vector<uint32_t>{2, 1, 2});
    CHECK_FALSE(flat.has_emitters);

    scene.materials[1].emission = Vec3(0, 0, 1);
    CHECK(flatten(scene).has_emitters);
}

TEST_CASE("flatten handles many triangles in parallel exactly as one by one", "[scenes][flatten]") {
    const Scene scene = generate_scene("gen:triangles?tris=50000&seed=9");
    Scene moved = scene;
    moved.instances[0].transform = translation({0, 0, -2});
    const FlatScene flat = flatten(moved);
    const Mesh& mesh = scene.meshes[0];
    REQUIRE(flat.triangles.size() == mesh.triangles.size());
    BBox bounds;
    bool all_equal = true;
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
        const Vec3 expected = mesh.positions[mesh.triangles[i].y] + Vec3(0, 0, -2);
        all_equal = all_equal && flat.triangles[i].v1 == expected;
        bounds.extend(BBox::of(flat.triangles[i]));
    }
    CHECK(all_equal);
    CHECK(flat.bounds.lower == bounds.lower);
    CHECK(flat.bounds.upper == bounds.upper);
}

TEST_CASE("auto_camera follows the benchmark rule", "[scenes][camera]") {
    const Camera camera = auto_camera(BBox{{0, 0, 0}, {2, 4, 4}});  // diagonal 6
    const float distance = 1.1f * 6.0f;
    const float norm = std::sqrt(0.35f * 0.35f + 1.0f);
    CHECK(camera.target == Vec3(1, 2, 2));
    CHECK(camera.eye.x == Approx(1.0f));
    CHECK(camera.eye.y == Approx(2.0f + distance * 0.35f / norm));
    CHECK(camera.eye.z == Approx(2.0f + distance / norm));
    CHECK(camera.up == Vec3(0, 1, 0));
    CHECK(camera.fov_deg == 50.0f);

    // A scene collapsed to a point still gets an eye off the target.
    const Camera point = auto_camera(BBox{{3, 3, 3}, {3, 3, 3}});
    CHECK(glm::length(point.eye - point.target) > 0.0f);
}
