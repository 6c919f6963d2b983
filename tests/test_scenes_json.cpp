// load_scene_json: cameras, meshes, instances, and every kind of bad field.
#include "scenes_test_support.h"

using namespace canopy;
using canopy::test::input_error_of;
using canopy::test::TempDir;
using Catch::Matchers::Contains;

namespace {

const char* const triangle_obj = "v 1 2 3\nv 0 0 0\nv 0 1 0\nf 1 2 3\n";

// A scene folder holding tri.obj and scene.json with the given text.
struct SceneFolder {
    TempDir dir;
    std::string json_path;

    explicit SceneFolder(const std::string& json) {
        dir.write("tri.obj", triangle_obj);
        json_path = dir.write("scene.json", json);
    }
};

std::string error_for(const std::string& json) {
    SceneFolder folder(json);
    return input_error_of([&] { load_scene_json(folder.json_path); });
}

const char* const mesh_list = R"("meshes": [{"name": "tri", "file": "tri.obj"}])";

std::string with_instance_transform(const std::string& transform) {
    return std::string("{") + mesh_list + R"(, "instances": [{"mesh": "tri", "transform": )" + transform + "}]}";
}

std::string with_camera(const std::string& camera) {
    return std::string(R"({"camera": )") + camera + ", " + mesh_list + "}";
}

}  // namespace

TEST_CASE("load_scene_json reads the camera and places every mesh once without instances", "[scenes][json]") {
    SceneFolder folder(R"({
        "camera": {"eye": [1, 2, 3], "target": [0, 0, -1], "up": [0, 0, 1], "fov": 35.5},
        "meshes": [{"name": "a", "file": "tri.obj"}, {"name": "b", "file": "./tri.obj"}]
    })");
    const Scene scene = load_scene_json(folder.json_path);
    test::check_mesh_invariants(scene);
    REQUIRE(scene.camera.has_value());
    CHECK(scene.camera->eye == Vec3(1, 2, 3));
    CHECK(scene.camera->target == Vec3(0, 0, -1));
    CHECK(scene.camera->up == Vec3(0, 0, 1));
    CHECK(scene.camera->fov_deg == 35.5f);
    REQUIRE(scene.meshes.size() == 2);
    CHECK(scene.meshes[1].name == "b");
    REQUIRE(scene.instances.size() == 2);
    CHECK(scene.instances[1].mesh == 1);
    CHECK(scene.instances[1].transform == glm::mat4(1.0f));
}

TEST_CASE("load_scene_json loads a mesh once however many instances place it", "[scenes][json]") {
    SceneFolder folder(std::string("{") + mesh_list + R"(, "instances": [{"mesh": "tri"}, {"mesh": "tri"}, {"mesh": "tri"}]})");
    const Scene scene = load_scene_json(folder.json_path);
    CHECK_FALSE(scene.camera.has_value());
    CHECK(scene.meshes.size() == 1);
    CHECK(scene.instances.size() == 3);
    CHECK(instanced_triangle_count(scene) == 3);
}

TEST_CASE("flatten applies a row-major transform: translation, rotation, non-uniform scale", "[scenes][json]") {
    // Rows of T(10, 20, 30) * Rz(90 degrees) * S(2, 3, 4): (x, y, z) -> (10 - 3y, 20 + 2x, 30 + 4z).
    SceneFolder folder(with_instance_transform("[0, -3, 0, 10,  2, 0, 0, 20,  0, 0, 4, 30,  0, 0, 0, 1]"));
    const FlatScene flat = flatten(load_scene_json(folder.json_path));
    REQUIRE(flat.triangles.size() == 1);
    CHECK(flat.triangles[0].v0 == Vec3(4, 22, 42));  // from (1, 2, 3)
    CHECK(flat.triangles[0].v1 == Vec3(10, 20, 30));  // from (0, 0, 0)
    CHECK(flat.triangles[0].v2 == Vec3(7, 20, 30));   // from (0, 1, 0)
    CHECK(flat.bounds.lower == Vec3(4, 20, 30));
    CHECK(flat.bounds.upper == Vec3(10, 22, 42));
}

TEST_CASE("load_scene_json names the file and the field of every bad entry", "[scenes][json][errors]") {
    struct Case {
        const char* what;
        std::string json;
        std::vector<const char*> expected;  // all in the message, besides the file name
    };
    const std::string tri_mesh = mesh_list;
    const Case cases[] = {
        {"a syntax error", "{\n  \"meshes\": [\n    {\"name\": \"a\" \"file\": \"tri.obj\"}\n  ]\n}", {"line 3"}},
        {"not an object", "[1, 2]", {"top level"}},
        {"no meshes", R"({"camera": {"eye": [0, 0, 1], "target": [0, 0, 0]}})", {"meshes", "missing"}},
        {"empty meshes", R"({"meshes": []})", {"meshes", "non-empty"}},
        {"meshes not an array", R"({"meshes": {"name": "a"}})", {"meshes"}},
        {"a numeric mesh name", R"({"meshes": [{"name": 7, "file": "tri.obj"}]})", {"meshes[0].name"}},
        {"a mesh without file", R"({"meshes": [{"name": "a"}]})", {"meshes[0].file", "missing"}},
        {"two meshes with one name", R"({"meshes": [{"name": "a", "file": "tri.obj"}, {"name": "a", "file": "tri.obj"}]})",
         {"meshes[1].name"}},
        {"an unknown field", "{" + tri_mesh + R"(, "instance": []})", {"instance", "unknown field"}},
        {"an unknown mesh field", R"({"meshes": [{"name": "a", "file": "tri.obj", "scale": 2}]})", {"meshes[0].scale"}},
        {"an unknown mesh name", "{" + tri_mesh + R"(, "instances": [{"mesh": "teapot"}]})", {"instances[0].mesh", "teapot"}},
        {"empty instances", "{" + tri_mesh + R"(, "instances": []})", {"instances"}},
        {"15 transform elements", with_instance_transform("[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0]"), {"instances[0].transform", "16"}},
        {"a string transform element", with_instance_transform(R"([1,0,0,"x", 0,1,0,0, 0,0,1,0, 0,0,0,1])"),
         {"instances[0].transform[3]"}},
        {"a non-finite transform element", with_instance_transform("[1,0,0,1e999, 0,1,0,0, 0,0,1,0, 0,0,0,1]"),
         {"instances[0].transform[3]", "finite"}},
        {"a singular transform", with_instance_transform("[1,0,0,0, 0,0,0,0, 0,0,1,0, 0,0,0,1]"),
         {"instances[0].transform", "singular"}},
        {"a rank-2 transform", with_instance_transform("[1,2,3,0, 2,4,6,0, 0,0,1,0, 0,0,0,1]"),
         {"instances[0].transform", "singular"}},
        {"a non-affine transform", with_instance_transform("[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,1,1]"),
         {"instances[0].transform", "0 0 0 1"}},
        {"eye equal to target", with_camera(R"({"eye": [1, 2, 3], "target": [1, 2, 3]})"), {"camera", "eye"}},
        {"up along the view", with_camera(R"({"eye": [0, 5, 0], "target": [0, 0, 0]})"), {"camera.up"}},
        {"a two-number eye", with_camera(R"({"eye": [1, 2], "target": [0, 0, 0]})"), {"camera.eye"}},
        {"a missing target", with_camera(R"({"eye": [1, 2, 3]})"), {"camera.target", "missing"}},
        {"fov 0", with_camera(R"({"eye": [0, 0, 1], "target": [0, 0, 0], "fov": 0})"), {"camera.fov"}},
        {"fov 180", with_camera(R"({"eye": [0, 0, 1], "target": [0, 0, 0], "fov": 180})"), {"camera.fov"}},
        {"fov as text", with_camera(R"({"eye": [0, 0, 1], "target": [0, 0, 0], "fov": "wide"})"), {"camera.fov"}},
        {"an infinite eye", with_camera(R"({"eye": [0, 0, -1e400], "target": [0, 0, 0]})"), {"camera.eye[2]"}},
        {"an eye beyond float range", with_camera(R"({"eye": [0, 1e300, 0], "target": [0, 0, 0]})"),
         {"camera.eye[1]", "float range"}},
        {"a missing mesh file", R"({"meshes": [{"name": "a", "file": "absent.obj"}]})", {"meshes[0].file", "absent.obj"}},
        {"a scene.json as a mesh", R"({"meshes": [{"name": "a", "file": "tri.obj"}, {"name": "b", "file": "scene.json"}]})",
         {"meshes[1].file: 'scene.json' is not a mesh file: expected .obj, .gltf or .glb"}},
        {"a mesh file without extension", R"({"meshes": [{"name": "a", "file": "tri"}]})",
         {"meshes[0].file: 'tri' is not a mesh file"}},
    };
    for (const Case& c : cases) {
        INFO(c.what);
        const std::string message = error_for(c.json);
        CHECK_THAT(message, Contains("scene.json"));
        for (const char* part : c.expected) CHECK_THAT(message, Contains(part));
    }
}

TEST_CASE("load_scene_json names the json, the field, the OBJ and its line for a bad mesh", "[scenes][json][errors]") {
    TempDir dir;
    dir.write("broken.obj", "v 0 0 0\nv 0 nan 0\n");
    const std::string json = dir.write("scene.json", R"({"meshes": [{"name": "b", "file": "broken.obj"}]})");
    CHECK_THAT(input_error_of([&] { load_scene_json(json); }),
               Contains("scene.json") && Contains("meshes[0].file") && Contains("broken.obj:2:"));
    CHECK_THAT(input_error_of([&] { load_scene_json(dir.file("absent.json")); }), Contains("absent.json"));
}
