// The real scenes in ../shared/scenes (skipped with a message when the folder is absent).
#include "scenes_test_support.h"

#include <filesystem>

using namespace canopy;

namespace {

bool shared_scenes_present() { return std::filesystem::is_directory(CANOPY_SHARED_SCENES); }

std::string shared(const std::string& relative) { return std::string(CANOPY_SHARED_SCENES) + "/" + relative; }

#define SKIP_WITHOUT_SHARED_SCENES()                                                           \
    if (!shared_scenes_present()) {                                                            \
        WARN("skipped: no shared scenes at " CANOPY_SHARED_SCENES);                            \
        SUCCEED();                                                                             \
        return;                                                                                \
    }

}  // namespace

TEST_CASE("shared OBJ files load with their known triangle counts", "[scenes][shared]") {
    SKIP_WITHOUT_SHARED_SCENES();
    const std::pair<const char*, uint64_t> files[] = {
        {"crytek-sponza/sponza.obj", 262'205},
        {"sibenik/sibenik.obj", 75'284},
        {"conference/conference.obj", 331'179},
        {"stanford-bunny/stanford-bunny.obj", 69'451},
        {"stanford-dragon-decimated/dragon.obj", 43'569},
        {"armadillo-decimated/armadillo.obj", 34'594},
        {"cornell-box/CornellBox-Original.obj", 36},
    };
    for (const auto& [file, triangles] : files) {
        INFO(file);
        const Scene scene = load_obj(shared(file));
        test::check_mesh_invariants(scene);
        CHECK(instanced_triangle_count(scene) == triangles);
    }
}

TEST_CASE("shared OBJ files have the README's object counts, one per o/g group", "[scenes][shared]") {
    SKIP_WITHOUT_SHARED_SCENES();
    const std::pair<const char*, size_t> files[] = {
        {"crytek-sponza/sponza.obj", 381},
        {"sibenik/sibenik.obj", 1},
        {"conference/conference.obj", 1},
        {"stanford-bunny/stanford-bunny.obj", 1},  // no o/g line: one object named after the file
        {"stanford-dragon-decimated/dragon.obj", 1},
        {"armadillo-decimated/armadillo.obj", 1},  // two materials, one group: one object
        {"cornell-box/CornellBox-Original.obj", 8},
    };
    for (const auto& [file, objects] : files) {
        INFO(file);
        CHECK(load_obj(shared(file)).meshes[0].objects.size() == objects);
    }
    CHECK(load_obj(shared("stanford-bunny/stanford-bunny.obj")).meshes[0].objects[0].name == "stanford-bunny");
}

TEST_CASE("crytek-sponza has 381 objects", "[scenes][shared]") {
    SKIP_WITHOUT_SHARED_SCENES();
    const Scene scene = load_scene(shared("crytek-sponza/scene.json"));
    CHECK(scene.name == "crytek-sponza");
    CHECK(scene.meshes[0].objects.size() == 381);
    CHECK(scene.camera.has_value());
}

TEST_CASE("cornell-box has 8 objects, one of them empty, and its .mtl colours", "[scenes][shared]") {
    SKIP_WITHOUT_SHARED_SCENES();
    const Scene scene = load_scene(shared("cornell-box/scene.json"));
    const Mesh& mesh = scene.meshes[0];
    // One object per g line, as written: the boxes' faces come before their g lines, so
    // "leftWall" also holds the short box, "shortBox" the tall box, and "tallBox" is empty.
    REQUIRE(mesh.objects.size() == 8);
    const std::pair<const char*, uint32_t> expected[] = {{"floor", 2},     {"ceiling", 2},  {"backWall", 2},
                                                         {"rightWall", 2}, {"leftWall", 14}, {"shortBox", 12},
                                                         {"tallBox", 0},   {"light", 2}};
    for (size_t i = 0; i < 8; ++i) {
        INFO("object " << i);
        CHECK(mesh.objects[i].name == expected[i].first);
        CHECK(mesh.objects[i].triangle_count == expected[i].second);
    }
    REQUIRE(mesh.triangle_material.size() == 36);
    const auto not_grey = [](const Material& m) { return m.kd != Vec3(0.8f); };
    CHECK(std::any_of(scene.materials.begin(), scene.materials.end(), not_grey));
    const FlatScene flat = flatten(scene);
    REQUIRE(flat.material.size() == 36);
    CHECK(flat.materials[flat.material[8]].name == "leftWall");
    CHECK(flat.materials[flat.material[8]].kd == Vec3(0.63f, 0.065f, 0.05f));
}

TEST_CASE("every shared scene.json loads; zoo-64 has 64 instances of 3 meshes", "[scenes][shared]") {
    SKIP_WITHOUT_SHARED_SCENES();
    for (const char* folder : {"armadillo-decimated", "conference", "cornell-box", "crytek-sponza", "sibenik",
                               "stanford-bunny", "stanford-dragon-decimated", "zoo-64", "zoo-1024"}) {
        INFO(folder);
        const Scene scene = load_scene(shared(std::string(folder) + "/scene.json"));
        test::check_mesh_invariants(scene);
        CHECK(scene.camera.has_value() == (std::string(folder) != "stanford-bunny"));
    }
    const Scene zoo = load_scene(shared("zoo-64/scene.json"));
    CHECK(zoo.meshes.size() == 3);
    CHECK(zoo.instances.size() == 64);
    CHECK(instanced_triangle_count(zoo) == 3'204'202);
    CHECK(load_scene(shared("zoo-1024/scene.json")).instances.size() == 1024);
}
