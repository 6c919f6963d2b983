// load_obj: groups, materials, triangulation, and every kind of bad input.
#include "scenes_test_support.h"

using namespace canopy;
using canopy::test::input_error_of;
using canopy::test::TempDir;
using Catch::Matchers::Contains;

namespace {

const char* const grouped_obj = R"(mtllib colours.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
vt 0 0
vn 0 0 1
f 1 2 3
o first
usemtl red
f 1 2 3 4
g second
usemtl blue
f -5 -4 -3 -2 -1
usemtl red
f 1/1/1 2//1 5/1
)";

const char* const colours_mtl = R"(newmtl red
Kd 1 0 0
map_Kd absent-red.png
newmtl blue
Kd 0 0 1
map_Kd absent-blue.png
bump absent-bump.png
)";

}  // namespace

TEST_CASE("load_obj makes one object per o/g group, in file order", "[scenes][obj]") {
    TempDir dir;
    dir.write("colours.mtl", colours_mtl);
    const Scene scene = load_obj(dir.write("grouped.obj", grouped_obj));
    test::check_mesh_invariants(scene);
    REQUIRE(scene.meshes.size() == 1);
    REQUIRE(scene.instances.size() == 1);
    CHECK(scene.instances[0].transform == glm::mat4(1.0f));
    const Mesh& mesh = scene.meshes[0];
    CHECK(mesh.positions.size() == 5);
    REQUIRE(mesh.triangles.size() == 1 + 2 + 3 + 1);  // triangle, quad, pentagon (fan), triangle
    REQUIRE(mesh.objects.size() == 3);
    CHECK(mesh.objects[0].name == "grouped");  // faces before any group: named after the file
    CHECK(mesh.objects[1].name == "first");
    CHECK(mesh.objects[2].name == "second");
    CHECK(mesh.objects[0].triangle_count == 1);
    CHECK(mesh.objects[1].triangle_count == 2);
    // Relative indices: -5 .. -1 are vertices 0 .. 4.
    CHECK(mesh.triangles[3] == glm::uvec3(0, 1, 2));
    CHECK(mesh.triangles[5] == glm::uvec3(0, 3, 4));
}

TEST_CASE("load_obj does not start an object where the material changes inside a group", "[scenes][obj]") {
    TempDir dir;
    dir.write("colours.mtl", colours_mtl);
    const Scene scene = load_obj(dir.write("grouped.obj", grouped_obj));
    const Mesh& mesh = scene.meshes[0];
    REQUIRE(mesh.objects.size() == 3);
    // "second" holds the blue pentagon and the red triangle after it: one object, two materials.
    CHECK(mesh.objects[2].first_triangle == 3);
    CHECK(mesh.objects[2].triangle_count == 3 + 1);
    CHECK(mesh.triangle_material[3] != mesh.triangle_material[6]);
}

TEST_CASE("load_obj keeps an empty o/g group as an object with 0 triangles", "[scenes][obj]") {
    TempDir dir;
    const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    const Scene scene = load_obj(dir.write("empty_groups.obj", triangle + "o lead\ng a\nf 1 2 3\ng hollow\n"
                                                                           "o b c\nf 1 2 3\nf 3 2 1\ng\ng tail\n"));
    test::check_mesh_invariants(scene);
    struct Expected {
        const char* name;
        uint32_t first_triangle, triangle_count;
    };
    // No faces before the first group, so no object named after the file there; a bare "g" is
    // named after the file; empty groups at the start, middle and end are all kept.
    const Expected expected[] = {{"lead", 0, 0}, {"a", 0, 1},            {"hollow", 1, 0},
                                 {"b c", 1, 2},  {"empty_groups", 3, 0}, {"tail", 3, 0}};
    const std::vector<Object>& objects = scene.meshes[0].objects;
    REQUIRE(objects.size() == std::size(expected));
    for (size_t i = 0; i < objects.size(); ++i) {
        INFO("object " << i);
        CHECK(objects[i].name == expected[i].name);
        CHECK(objects[i].first_triangle == expected[i].first_triangle);
        CHECK(objects[i].triangle_count == expected[i].triangle_count);
    }
}

TEST_CASE("load_obj reads Kd, gives unmaterialled faces a default, warns once about absent textures",
          "[scenes][obj]") {
    TempDir dir;
    dir.write("colours.mtl", colours_mtl);
    test::CaptureStderr stderr_capture;
    const Scene scene = load_obj(dir.write("grouped.obj", grouped_obj));
    const std::string warnings = stderr_capture.text();

    REQUIRE(scene.materials.size() == 3);
    CHECK(scene.materials[0].name == "red");
    CHECK(scene.materials[0].kd == Vec3(1, 0, 0));
    CHECK(scene.materials[1].kd == Vec3(0, 0, 1));
    CHECK(scene.materials[2].kd == Vec3(0.8f));  // for the face before any usemtl
    CHECK(scene.meshes[0].triangle_material == std::vector<uint32_t>{2, 0, 0, 1, 1, 1, 0});

    CHECK(std::count(warnings.begin(), warnings.end(), '\n') == 1);
    CHECK_THAT(warnings, Contains("grouped.obj") && Contains("3 texture file(s)"));
}

TEST_CASE("load_obj reads Ke as the material's emission, zero where the .mtl has none", "[scenes][obj]") {
    TempDir dir;
    dir.write("lit.mtl", "newmtl lamp\nKd 0.5 0.5 0.5\nKe 17 12 4\nnewmtl wall\nKd 1 1 1\n");
    const Scene scene = load_obj(dir.write("lit.obj", "mtllib lit.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                                      "usemtl lamp\nf 1 2 3\nusemtl wall\nf 1 3 2\n"));
    REQUIRE(scene.materials.size() == 2);
    CHECK(scene.materials[0].emission == Vec3(17, 12, 4));
    CHECK(scene.materials[1].emission == Vec3(0));
    CHECK(flatten(scene).has_emitters);
}

TEST_CASE("load_obj without materials leaves triangle_material empty", "[scenes][obj]") {
    TempDir dir;
    const Scene plain = load_obj(dir.write("plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
    CHECK(plain.materials.empty());
    CHECK(plain.meshes[0].triangle_material.empty());

    test::CaptureStderr stderr_capture;  // an absent .mtl is a warning, like absent textures
    const Scene no_mtl = load_obj(dir.write("no_mtl.obj", "mtllib gone.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
    CHECK(no_mtl.materials.empty());
    CHECK(no_mtl.meshes[0].triangle_material.empty());
    CHECK_THAT(stderr_capture.text(), Contains("no_mtl.obj") && Contains("gone.mtl"));
}

TEST_CASE("load_obj keeps degenerate triangles and accepts forward references, CRLF and '+'", "[scenes][obj]") {
    TempDir dir;
    const Scene scene = load_obj(dir.write("odd.obj", "f 1 2 3\r\nf 1 1 1\r\nv +0 0 0\r\nv 1 0 0\r\nv 0 1 0 1.0\r\n"));
    test::check_mesh_invariants(scene);
    REQUIRE(scene.meshes[0].triangles.size() == 2);
    CHECK(scene.meshes[0].triangles[1] == glm::uvec3(0, 0, 0));
}

TEST_CASE("load_obj names the file and the line of every malformed entry", "[scenes][obj][errors]") {
    TempDir dir;
    const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    struct Case {
        const char* what;
        std::string text;
        const char* line;  // ":N:" in the message
        const char* detail;
    };
    const Case cases[] = {
        {"a non-number", "v 0 0 0\nv 1 abc 0\n", ":2:", "abc"},
        {"a number with trailing junk", "v 0 0 0\nv 1 2.5x 0\n", ":2:", "2.5x"},
        {"too few coordinates", "v 0 0 0\nv 1 2\n", ":2:", "3 coordinates"},
        {"nan", triangle + "v nan 0 0\n", ":4:", "nan"},
        {"inf", triangle + "v 0 inf 0\n", ":4:", "inf"},
        {"-Infinity", "# comment\n" + triangle + "v 0 0 -Infinity\n", ":5:", "Infinity"},
        {"a float overflow", triangle + "v 1e39 0 0\n", ":4:", "1e39"},
        {"an index past the last vertex", triangle + "f 1 2 7\nv 1 1 1\n", ":4:", "out of range"},
        {"index zero", triangle + "f 0 1 2\n", ":4:", "0"},
        {"a relative index before the first vertex", triangle + "f -4 -1 -2\n", ":4:", "-4"},
        {"a face with two vertices", triangle + "f 1 2\n", ":4:", "at least 3"},
        {"a face with no vertices", triangle + "f\n", ":4:", "at least 3"},
        {"a non-index face vertex", triangle + "f 1 2 x\n", ":4:", "'x'"},
        {"a fractional index", triangle + "f 1 2 3.5\n", ":4:", "3.5"},
        {"bad lines counted with CRLF", "v 0 0 0\r\nv nan 0 0\r\n", ":2:", "nan"},
    };
    for (const Case& c : cases) {
        INFO(c.what);
        const std::string path = dir.write("bad.obj", c.text);
        const std::string message = input_error_of([&] { load_obj(path); });
        CHECK_THAT(message, Contains("bad.obj") && Contains(c.line) && Contains(c.detail));
    }
}

TEST_CASE("load_obj rejects a missing file and an OBJ with no faces", "[scenes][obj][errors]") {
    TempDir dir;
    CHECK_THAT(input_error_of([&] { load_obj(dir.file("absent.obj")); }), Contains("absent.obj"));
    CHECK_THAT(input_error_of([&] { load_obj(dir.write("empty.obj", "")); }), Contains("empty.obj") && Contains("no faces"));
    CHECK_THAT(input_error_of([&] { load_obj(dir.write("points.obj", "v 0 0 0\nv 1 1 1\n")); }),
               Contains("points.obj") && Contains("no faces"));
    CHECK_THAT(input_error_of([&] { load_scene(dir.write("empty2.obj", "# nothing\n")); }), Contains("empty2.obj"));
}
