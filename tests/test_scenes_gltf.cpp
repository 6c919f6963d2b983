// load_gltf: triangles from every kind of accessor, node transforms as instances, the camera, materials, the
// three ways of storing a buffer (data URI, .bin file, .glb), scene.json meshes from glTF, and every kind of bad file.
#include "scenes_test_support.h"

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <functional>
#include <iterator>
#include <random>

using namespace canopy;
using canopy::test::input_error_of;
using canopy::test::TempDir;
using Catch::Matchers::Contains;
using nlohmann::json;

namespace {

constexpr int kFloat = 5126, kUnsignedByte = 5121, kUnsignedShort = 5123, kUnsignedInt = 5125;

std::string base64(const std::string& bytes) {
    static const char digits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string text;
    for (size_t i = 0; i < bytes.size(); i += 3) {
        uint32_t group = uint32_t(uint8_t(bytes[i])) << 16;
        if (i + 1 < bytes.size()) group |= uint32_t(uint8_t(bytes[i + 1])) << 8;
        if (i + 2 < bytes.size()) group |= uint32_t(uint8_t(bytes[i + 2]));
        for (size_t k = 0; k < 4; ++k) text += i + k <= bytes.size() ? digits[(group >> (18 - 6 * k)) & 63] : '=';
    }
    return text;
}

// A glTF document under construction: binary data in one buffer, the JSON open to tests that break it.
class GltfBuilder {
public:
    json root = {{"asset", {{"version", "2.0"}}},
                 {"buffers", json::array()},
                 {"bufferViews", json::array()},
                 {"accessors", json::array()},
                 {"meshes", json::array()},
                 {"nodes", json::array()},
                 {"scenes", {{{"nodes", json::array()}}}}};

    // Appends the bytes of `values` and a view and an accessor over them; returns the accessor's index.
    template <class T>
    int accessor(const std::vector<T>& values, int component_type, const char* type, size_t count) {
        const size_t offset = append(values.data(), values.size() * sizeof(T));
        root["bufferViews"].push_back(
            {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", values.size() * sizeof(T)}});
        root["accessors"].push_back({{"bufferView", root["bufferViews"].size() - 1},
                                     {"componentType", component_type},
                                     {"type", type},
                                     {"count", count}});
        return int(root["accessors"].size()) - 1;
    }
    int positions(const std::vector<float>& xyz) { return accessor(xyz, kFloat, "VEC3", xyz.size() / 3); }
    template <class Index>
    int indices(const std::vector<Index>& values, int component_type) {
        return accessor(values, component_type, "SCALAR", values.size());
    }

    int mesh(const std::vector<json>& primitives) {
        root["meshes"].push_back({{"primitives", primitives}});
        return int(root["meshes"].size()) - 1;
    }
    // A node, listed among the scene's roots when `root_node`; returns its index.
    int node(const json& fields, bool root_node = true) {
        root["nodes"].push_back(fields);
        const int index = int(root["nodes"].size()) - 1;
        if (root_node) root["scenes"][0]["nodes"].push_back(index);
        return index;
    }

    std::string write_gltf(const TempDir& dir, const std::string& name) {
        root["buffers"] = {
            {{"byteLength", data_.size()}, {"uri", "data:application/octet-stream;base64," + base64(data_)}}};
        return dir.write(name, root.dump());
    }
    std::string write_gltf_and_bin(const TempDir& dir, const std::string& name) {
        dir.write(name + ".bin", data_);
        root["buffers"] = {{{"byteLength", data_.size()}, {"uri", name + ".bin"}}};
        return dir.write(name, root.dump());
    }
    // Binary glTF: a 12-byte header, then a JSON chunk and a BIN chunk, each padded to 4 bytes.
    std::string write_glb(const TempDir& dir, const std::string& name) {
        root["buffers"] = {{{"byteLength", data_.size()}}};
        const std::string text = padded(root.dump(), ' '), bin = padded(data_, '\0');
        std::string file = "glTF";
        put_u32(file, 2), put_u32(file, uint32_t(12 + 8 + text.size() + 8 + bin.size()));
        put_u32(file, uint32_t(text.size())), file += "JSON", file += text;
        put_u32(file, uint32_t(bin.size())), file += std::string("BIN\0", 4), file += bin;
        return dir.write(name, file);
    }

private:
    size_t append(const void* bytes, size_t size) {
        data_ = padded(data_, '\0');  // accessors must start 4-byte aligned
        const size_t offset = data_.size();
        data_.append(static_cast<const char*>(bytes), size);
        return offset;
    }
    static std::string padded(std::string bytes, char fill) { return bytes.append((4 - bytes.size() % 4) % 4, fill); }
    static void put_u32(std::string& out, uint32_t value) { out.append(reinterpret_cast<const char*>(&value), 4); }

    std::string data_;
};

// A unit right triangle in the xy plane, not indexed.
json triangle_primitive(GltfBuilder& gltf) {
    return {{"attributes", {{"POSITION", gltf.positions({0, 0, 0, 1, 0, 0, 0, 1, 0})}}}};
}

// One triangle mesh placed twice: at x = 10 (a translation around a scaled child) and by a matrix at y = 5.
GltfBuilder two_placements() {
    GltfBuilder gltf;
    const int mesh = gltf.mesh({triangle_primitive(gltf)});
    const int child = gltf.node({{"mesh", mesh}, {"scale", {2, 2, 2}}}, false);
    gltf.node({{"translation", {10, 0, 0}}, {"children", {child}}});
    gltf.node({{"mesh", mesh}, {"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1}}});
    return gltf;
}

Vec3 placed(const Instance& instance, const Vec3& p) {
    return Vec3(instance.transform * glm::vec4(p, 1.0f));
}

}  // namespace

TEST_CASE("load_gltf reads triangles through 8-, 16- and 32-bit indices, or none", "[scenes][gltf]") {
    TempDir dir;
    GltfBuilder gltf;
    const std::vector<float> square{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const std::vector<json> primitives = {{{"attributes", {{"POSITION", gltf.positions(square)}}},
                                           {"indices", gltf.indices<uint8_t>({0, 1, 2, 0, 2, 3}, kUnsignedByte)}},
                                          {{"attributes", {{"POSITION", gltf.positions(square)}}},
                                           {"indices", gltf.indices<uint16_t>({3, 2, 1}, kUnsignedShort)}},
                                          {{"attributes", {{"POSITION", gltf.positions(square)}}},
                                           {"indices", gltf.indices<uint32_t>({1, 3, 0}, kUnsignedInt)}},
                                          triangle_primitive(gltf)};
    gltf.node({{"mesh", gltf.mesh(primitives)}});
    const Scene scene = load_gltf(gltf.write_gltf(dir, "square.gltf"));
    test::check_mesh_invariants(scene);
    REQUIRE(scene.meshes.size() == 1);
    const Mesh& mesh = scene.meshes[0];
    CHECK(mesh.positions.size() == 4 + 4 + 4 + 3);
    REQUIRE(mesh.triangles.size() == 2 + 1 + 1 + 1);
    CHECK(mesh.triangles[1] == glm::uvec3(0, 2, 3));
    CHECK(mesh.triangles[2] == glm::uvec3(7, 6, 5));  // after the first primitive's 4 vertices
    CHECK(mesh.triangles[3] == glm::uvec3(9, 11, 8));
    CHECK(mesh.triangles[4] == glm::uvec3(12, 13, 14));
    CHECK(mesh.positions[6] == Vec3(1, 1, 0));
    REQUIRE(mesh.objects.size() == 1);  // a glTF mesh is one object, whatever its primitives
    CHECK(mesh.objects[0].triangle_count == 5);
    CHECK(scene.materials.empty());
    CHECK(mesh.triangle_material.empty());
    CHECK_FALSE(scene.camera);
}

TEST_CASE("load_gltf respects the accessor's byteOffset and the buffer view's byteStride", "[scenes][gltf]") {
    TempDir dir;
    GltfBuilder gltf;
    // Interleaved: 4 bytes of something else, then x y z, per 16-byte vertex.
    const std::vector<float> interleaved{-1, 0, 0, 0, -1, 1, 0, 0, -1, 0, 1, 0};
    const int accessor = gltf.accessor(interleaved, kFloat, "VEC3", 3);
    gltf.root["bufferViews"][0]["byteStride"] = 16;
    gltf.root["accessors"][0]["byteOffset"] = 4;
    gltf.node({{"mesh", gltf.mesh({{{"attributes", {{"POSITION", accessor}}}}})}});
    const Scene scene = load_gltf(gltf.write_gltf(dir, "interleaved.gltf"));
    REQUIRE(scene.meshes[0].positions.size() == 3);
    CHECK(scene.meshes[0].positions == std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
}

TEST_CASE("load_gltf makes each node placing a mesh an instance, through the hierarchy's transforms",
          "[scenes][gltf]") {
    TempDir dir;
    GltfBuilder gltf = two_placements();
    // The same scene from a data URI, a .bin beside the file, and a binary .glb.
    for (const std::string& path :
         {gltf.write_gltf(dir, "two.gltf"), gltf.write_gltf_and_bin(dir, "bin.gltf"), gltf.write_glb(dir, "two.glb")}) {
        INFO(path);
        const Scene scene = load_gltf(path);
        test::check_mesh_invariants(scene);
        CHECK(scene.name == std::filesystem::path(path).stem().string());
        REQUIRE(scene.meshes.size() == 1);
        REQUIRE(scene.instances.size() == 2);
        CHECK(scene.instances[0].mesh == 0);
        CHECK(scene.instances[1].mesh == 0);
        CHECK(placed(scene.instances[0], Vec3(1, 0, 0)) == Vec3(12, 0, 0));  // scaled by 2, then moved by 10
        CHECK(placed(scene.instances[1], Vec3(1, 0, 0)) == Vec3(1, 5, 0));
        CHECK(instanced_triangle_count(scene) == 2);
    }
}

TEST_CASE("load_gltf composes translation, rotation and scale in that order", "[scenes][gltf]") {
    TempDir dir;
    GltfBuilder gltf;
    const double half = std::sqrt(0.5);  // a quarter turn about +z: x goes to y
    gltf.node({{"mesh", gltf.mesh({triangle_primitive(gltf)})},
               {"translation", {0, 0, 3}},
               {"rotation", {0, 0, half, half}},
               {"scale", {2, 1, 1}}});
    const Scene scene = load_gltf(gltf.write_gltf(dir, "trs.gltf"));
    const Vec3 p = placed(scene.instances.at(0), Vec3(1, 0, 0));
    CHECK(p.x == Approx(0).margin(1e-6));
    CHECK(p.y == Approx(2));
    CHECK(p.z == Approx(3));
}

TEST_CASE("load_gltf takes the first perspective camera, placed by its node", "[scenes][gltf][camera]") {
    TempDir dir;
    GltfBuilder gltf = two_placements();
    gltf.root["cameras"] = {
        {{"type", "orthographic"}, {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"zfar", 10}, {"znear", 0.1}}}},
        {{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}}}}};
    gltf.node({{"camera", 0}, {"translation", {0, 0, -4}}});
    const double half = std::sqrt(0.5);  // a quarter turn about +y: the camera's -z looks along -x
    gltf.node({{"camera", 1}, {"translation", {7, 1, 2}}, {"rotation", {0, half, 0, half}}});
    const Scene scene = load_scene(gltf.write_glb(dir, "camera.glb"));
    REQUIRE(scene.camera);
    CHECK(scene.camera->eye == Vec3(7, 1, 2));
    const Vec3 forward = glm::normalize(scene.camera->target - scene.camera->eye);
    CHECK(forward.x == Approx(-1));
    CHECK(forward.z == Approx(0).margin(1e-6));
    CHECK(scene.camera->up.y == Approx(1));
    CHECK(scene.camera->fov_deg == Approx(0.5 * 180.0 / 3.14159265358979));  // radians in glTF, degrees in canopy
}

TEST_CASE("load_gltf reads baseColorFactor as kd and emissiveFactor (times its strength) as emission",
          "[scenes][gltf][materials]") {
    TempDir dir;
    GltfBuilder gltf;
    gltf.root["materials"] = {{{"name", "red"}, {"pbrMetallicRoughness", {{"baseColorFactor", {1, 0, 0, 1}}}}},
                              {{"emissiveFactor", {1, 0.5, 0.25}},
                               {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 4}}}}}}};
    json red = triangle_primitive(gltf), lamp = triangle_primitive(gltf), plain = triangle_primitive(gltf);
    red["material"] = 0, lamp["material"] = 1;
    gltf.node({{"mesh", gltf.mesh({red, lamp, plain})}});
    const Scene scene = load_gltf(gltf.write_gltf(dir, "lit.gltf"));
    test::check_mesh_invariants(scene);
    REQUIRE(scene.materials.size() == 3);
    CHECK(scene.materials[0].name == "red");
    CHECK(scene.materials[0].kd == Vec3(1, 0, 0));
    CHECK(scene.materials[0].emission == Vec3(0));
    CHECK(scene.materials[1].kd == Vec3(1));  // glTF's default base colour
    CHECK(scene.materials[1].emission == Vec3(4, 2, 1));
    CHECK(scene.materials[2].kd == Vec3(0.8f));  // for the primitive without a material
    CHECK(scene.meshes[0].triangle_material == std::vector<uint32_t>{0, 1, 2});
    CHECK(flatten(scene).has_emitters);
}

TEST_CASE("a scene.json mesh may be a glTF file, its node hierarchy baked into one mesh", "[scenes][gltf][json]") {
    TempDir dir;
    GltfBuilder gltf = two_placements();
    gltf.write_glb(dir, "two.glb");
    const Scene scene = load_scene(dir.write("scene.json", R"({"meshes": [{"name": "pair", "file": "two.glb"}],
        "instances": [{"mesh": "pair"}, {"mesh": "pair", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,100, 0,0,0,1]}]})"));
    test::check_mesh_invariants(scene);
    REQUIRE(scene.meshes.size() == 1);
    CHECK(scene.meshes[0].name == "pair");
    CHECK(scene.meshes[0].objects.size() == 2);  // one per glTF placement
    CHECK(scene.meshes[0].positions[1] == Vec3(12, 0, 0));
    CHECK(scene.meshes[0].positions[4] == Vec3(1, 5, 0));
    CHECK(scene.instances.size() == 2);
    CHECK(instanced_triangle_count(scene) == 4);
}

TEST_CASE("load_gltf names the file and the field of every malformed entry", "[scenes][gltf][errors]") {
    TempDir dir;
    const auto error_after = [&](const std::function<void(GltfBuilder&)>& damage) {
        GltfBuilder gltf;
        const int indices = gltf.indices<uint16_t>({0, 1, 2}, kUnsignedShort);
        const int positions = gltf.positions({0, 0, 0, 1, 0, 0, 0, 1, 0});
        gltf.node({{"mesh", gltf.mesh({{{"attributes", {{"POSITION", positions}}}, {"indices", indices}}})}});
        damage(gltf);
        return input_error_of([&] { load_gltf(gltf.write_gltf(dir, "bad.gltf")); });
    };
    // The message names the file and the field, then says what is wrong.
    const auto check_names = [](const std::string& message, const std::string& field, const std::string& problem) {
        CHECK_THAT(message, Contains("bad.gltf: " + field + ": ") && Contains(problem));
    };
    check_names(error_after([](GltfBuilder& g) { g.root["accessors"][0]["count"] = 4; }), "accessors[0]",
                "reach beyond the 6 bytes of its buffer view");
    check_names(error_after([](GltfBuilder& g) { g.root["accessors"][1]["byteOffset"] = 4; }), "accessors[1]",
                "reach beyond");
    check_names(error_after([](GltfBuilder& g) { g.root["bufferViews"][1]["byteLength"] = 400; }), "bufferViews[1]",
                "bytes of its buffer");
    check_names(error_after([](GltfBuilder& g) { g.root["bufferViews"][1]["byteStride"] = 8; }),
                "bufferViews[1].byteStride", "less than the 12 bytes");
    check_names(error_after([](GltfBuilder& g) { g.root["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 7; }),
                "meshes[0].primitives[0].attributes.POSITION", "accessor 7 does not exist");
    check_names(error_after([](GltfBuilder& g) { g.root["meshes"][0]["primitives"][0]["mode"] = 1; }),
                "meshes[0].primitives[0].mode", "1 (LINES) is not supported");
    check_names(
        error_after([](GltfBuilder& g) { g.root["meshes"][0]["primitives"][0]["attributes"].erase("POSITION"); }),
        "meshes[0].primitives[0].attributes", "no POSITION");
    check_names(error_after([](GltfBuilder& g) { g.root["accessors"][0]["count"] = 2; }), "meshes[0].primitives[0]",
                "2 vertex indices do not make whole triangles");
    check_names(error_after([](GltfBuilder& g) { g.root["accessors"][1]["componentType"] = kUnsignedShort; }),
                "accessors[1]", "must hold float VEC3");
    check_names(error_after([](GltfBuilder& g) { g.root["meshes"][0]["primitives"][0]["material"] = 3; }),
                "meshes[0].primitives[0].material", "material 3 does not exist");
    check_names(error_after([](GltfBuilder& g) { g.root["nodes"][0]["mesh"] = 5; }), "nodes[0].mesh", "mesh 5");
    check_names(error_after([](GltfBuilder& g) { g.root["nodes"][0]["children"] = json::array({0}); }),
                "nodes[0].children", "node 0 has two parents (or is in a cycle)");
    check_names(error_after([](GltfBuilder& g) { g.root["nodes"][0]["scale"] = {0, 1, 1}; }), "nodes[0]", "singular");
    check_names(error_after([](GltfBuilder& g) {
                    g.root["nodes"][0]["translation"] = {1, 2};
                }),
                "nodes[0].translation", "must have 3 numbers");
    check_names(error_after([](GltfBuilder& g) { g.root.erase("scenes"); }), "scenes", "no scene");
}

TEST_CASE("load_gltf rejects out-of-range indices and non-finite positions in the binary data",
          "[scenes][gltf][errors]") {
    TempDir dir;
    GltfBuilder out_of_range;
    const int positions = out_of_range.positions({0, 0, 0, 1, 0, 0, 0, 1, 0});
    out_of_range.node(
        {{"mesh", out_of_range.mesh({{{"attributes", {{"POSITION", positions}}},
                                      {"indices", out_of_range.indices<uint32_t>({0, 1, 9}, kUnsignedInt)}}})}});
    CHECK_THAT(input_error_of([&] { load_gltf(out_of_range.write_glb(dir, "range.glb")); }),
               Contains("range.glb: accessors[1]") &&
                   Contains("index 9 (element 2) is out of range: POSITION has 3 vertices"));

    GltfBuilder not_finite;
    not_finite.node(
        {{"mesh",
          not_finite.mesh({{{"attributes", {{"POSITION", not_finite.positions({0, 0, 0, 1, NAN, 0, 0, 1, 0})}}}}})}});
    CHECK_THAT(input_error_of([&] { load_gltf(not_finite.write_glb(dir, "nan.glb")); }),
               Contains("nan.glb: accessors[0]") && Contains("position 1 is not finite"));
}

TEST_CASE("load_gltf names the file when it is missing, truncated anywhere, or its buffer is absent",
          "[scenes][gltf][errors]") {
    TempDir dir;
    CHECK_THAT(input_error_of([&] { load_gltf(dir.file("absent.gltf")); }), Contains("absent.gltf: no such file"));
    CHECK_THAT(input_error_of([&] { load_gltf(dir.write("text.gltf", "{\"asset\": ")); }), Contains("text.gltf: "));

    GltfBuilder gltf = two_placements();
    // Cut anywhere: in the header, a chunk header, the JSON or the binary data.
    const std::pair<std::string, std::string> files[] = {{gltf.write_glb(dir, "whole.glb"), "cut.glb"},
                                                         {gltf.write_gltf(dir, "whole.gltf"), "cut.gltf"}};
    for (const auto& file : files) {
        const std::string& whole = file.first;
        const std::string& cut = file.second;  // not a structured binding: the lambda below captures it (clang 14)
        std::ifstream in(whole, std::ios::binary);
        const std::string bytes{std::istreambuf_iterator<char>(in), {}};
        for (size_t length = 0; length < bytes.size(); ++length) {
            INFO(cut << " truncated to " << length << " of " << bytes.size() << " bytes");
            CHECK_THAT(input_error_of([&] { load_gltf(dir.write(cut, bytes.substr(0, length))); }),
                       Contains(cut + ": "));
        }
    }

    gltf.write_gltf_and_bin(dir, "lost.gltf");
    std::filesystem::remove(dir.file("lost.gltf.bin"));
    CHECK(input_error_of([&] { load_gltf(dir.file("lost.gltf")); }) ==
          dir.file("lost.gltf") + ": buffers[0].uri: 'lost.gltf.bin' does not exist (looked for " +
              dir.file("lost.gltf.bin") + ")");
    // The fuzz corpus's file: its buffer.bin was never there.
    const std::string external = CANOPY_SOURCE_DIR "/fuzz/corpus/gltf/external.gltf";
    CHECK_THAT(input_error_of([&] { load_gltf(external); }),
               Contains("external.gltf: buffers[0].uri: 'buffer.bin' does not exist (looked for " CANOPY_SOURCE_DIR
                        "/fuzz/corpus/gltf/buffer.bin)"));
}

TEST_CASE("load_gltf survives damaged bytes anywhere: the file loads or is an InputError, never a crash",
          "[scenes][gltf][errors]") {
    TempDir dir;
    GltfBuilder gltf = two_placements();
    for (const std::string& whole : {gltf.write_glb(dir, "whole.glb"), gltf.write_gltf(dir, "whole.gltf")}) {
        std::ifstream in(whole, std::ios::binary);
        const std::string bytes{std::istreambuf_iterator<char>(in), {}};
        const std::string damaged_name = "damaged" + std::filesystem::path(whole).extension().string();
        std::mt19937 rng(1);
        for (int trial = 0; trial < 1000; ++trial) {
            std::string damaged = bytes;
            // Random bytes, or JSON's digits and delimiters, which keep the parser going into the fields.
            for (uint32_t k = 0, n = 1 + rng() % 3; k < n; ++k)
                damaged[rng() % damaged.size()] = rng() % 2 ? char(rng()) : "0123456789-.e,]}\""[rng() % 17];
            INFO(damaged_name << ", trial " << trial);
            try {
                load_gltf(dir.write(damaged_name, damaged));
            } catch (const InputError&) {  // any other exception fails the test
            }
        }
    }
}
