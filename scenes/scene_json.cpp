// scene.json loading (format: ../shared/scenes/README.md). Every field is checked, and every
// error names the file and the field, e.g. "zoo/scene.json: instances[3].transform: ...".
#include "scenes/loaders.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>

namespace canopy {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Follows nlohmann's parse events to know which field is being read when parsing fails.
class FieldTracker {
public:
    bool operator()(int /*depth*/, json::parse_event_t event, json& parsed) {
        switch (event) {
        case json::parse_event_t::object_start: levels_.push_back({false, 0, {}}); break;
        case json::parse_event_t::array_start: levels_.push_back({true, 0, {}}); break;
        case json::parse_event_t::key: levels_.back().key = parsed.get<std::string>(); break;
        case json::parse_event_t::object_end:
        case json::parse_event_t::array_end:
            levels_.pop_back();
            element_done();
            break;
        case json::parse_event_t::value: element_done(); break;
        }
        return true;
    }

    std::string field() const {
        std::string path;
        for (const Level& level : levels_)
            path += level.array ? "[" + std::to_string(level.index) + "]" : (path.empty() ? "" : ".") + level.key;
        return path;
    }

private:
    struct Level {
        bool array;
        size_t index;  // arrays: elements read so far, so the one being read
        std::string key;
    };

    void element_done() {
        if (!levels_.empty() && levels_.back().array) ++levels_.back().index;
    }

    std::vector<Level> levels_;
};

class SceneFile {
public:
    explicit SceneFile(std::string path) : path_(std::move(path)) {}

    const std::string& path() const { return path_; }

    [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
        throw InputError(path_ + ": " + (field.empty() ? "" : field + ": ") + problem);
    }

    json parse() const {
        require_regular_file(path_);
        std::ifstream in(path_);
        if (!in) throw InputError(path_ + ": cannot be read");
        FieldTracker tracker;
        try {
            return json::parse(in, std::ref(tracker));
        } catch (const json::parse_error& e) {  // its message names the line and column
            throw InputError(path_ + ": JSON " + without_exception_id(e.what()));
        } catch (const json::exception& e) {  // 1e999: no position in the message, so name the field
            fail(tracker.field(), "is not a finite number (" + without_exception_id(e.what()) + ")");
        }
    }

    // Unknown keys are errors: a misspelt "instance" would otherwise be silently ignored.
    void expect_object(const json& value, const std::string& field, std::initializer_list<const char*> keys) const {
        if (!value.is_object()) fail(field, field.empty() ? "the top level must be an object" : "must be an object");
        for (const auto& item : value.items()) {  // no structured binding: clang before 16 cannot capture one
            const std::string& key = item.key();
            if (std::find_if(keys.begin(), keys.end(), [&](const char* k) { return key == k; }) == keys.end())
                fail(join(field, key.c_str()), "unknown field");
        }
    }

    const json& required(const json& object, const std::string& field, const char* key) const {
        if (!object.contains(key)) fail(join(field, key), "missing");
        return object[key];
    }

    // Finite: JSON has no nan or inf, and parse() rejects overflow. Yet canopy stores floats.
    double number(const json& value, const std::string& field) const {
        if (!value.is_number()) fail(field, "must be a number, got " + excerpt(value));
        const double x = value.get<double>();
        if (!(std::abs(x) <= double(std::numeric_limits<float>::max()))) fail(field, excerpt(value) + " is beyond float range");
        return x;
    }

    std::vector<double> numbers(const json& value, const std::string& field, size_t count) const {
        if (!value.is_array() || value.size() != count)
            fail(field, "must be an array of " + std::to_string(count) + " numbers, got " + excerpt(value));
        std::vector<double> result;
        for (size_t i = 0; i < count; ++i) result.push_back(number(value[i], field + "[" + std::to_string(i) + "]"));
        return result;
    }

    Vec3 vec3(const json& value, const std::string& field) const {
        const std::vector<double> v = numbers(value, field, 3);
        return Vec3(float(v[0]), float(v[1]), float(v[2]));
    }

    std::string text(const json& value, const std::string& field) const {
        if (!value.is_string() || value.get<std::string>().empty())
            fail(field, "must be a non-empty string, got " + excerpt(value));
        return value.get<std::string>();
    }

    const json& array(const json& value, const std::string& field) const {
        if (!value.is_array() || value.empty()) fail(field, "must be a non-empty array");
        return value;
    }

    static std::string join(const std::string& field, const char* key) {
        return field.empty() ? key : field + "." + key;
    }

private:
    static std::string excerpt(const json& value) {
        const std::string text = value.dump();
        return text.size() <= 60 ? text : text.substr(0, 57) + "...";
    }

    // nlohmann prefixes "[json.exception.parse_error.101] "; the rest names line and column.
    static std::string without_exception_id(const std::string& message) {
        const size_t end = message.find("] ");
        return end == std::string::npos ? message : message.substr(end + 2);
    }

    std::string path_;
};

Camera parse_camera(const SceneFile& file, const json& value) {
    file.expect_object(value, "camera", {"eye", "target", "up", "fov"});
    Camera camera;
    camera.eye = file.vec3(file.required(value, "camera", "eye"), "camera.eye");
    camera.target = file.vec3(file.required(value, "camera", "target"), "camera.target");
    if (value.contains("up")) camera.up = file.vec3(value["up"], "camera.up");
    if (value.contains("fov")) {
        const double fov = file.number(value["fov"], "camera.fov");
        if (!(fov > 0.0 && fov < 180.0)) file.fail("camera.fov", "must be in (0, 180) degrees, got " + std::to_string(fov));
        camera.fov_deg = float(fov);
    }
    const Vec3 forward = camera.target - camera.eye;
    if (glm::length(forward) == 0.0f) file.fail("camera.target", "equals camera.eye: no view direction");
    if (glm::length(glm::cross(glm::normalize(forward), camera.up)) < 1e-6f)
        file.fail("camera.up", "is zero or parallel to the view direction");
    return camera;
}

// Each mesh is loaded once, however many instances place it.
std::map<std::string, uint32_t> load_meshes(const SceneFile& file, const json& meshes, Scene& scene) {
    std::map<std::string, uint32_t> index_of;
    const fs::path directory = fs::path(file.path()).parent_path();
    for (size_t i = 0; i < meshes.size(); ++i) {
        const std::string field = "meshes[" + std::to_string(i) + "]";
        file.expect_object(meshes[i], field, {"name", "file"});
        const std::string name = file.text(file.required(meshes[i], field, "name"), field + ".name");
        const std::string relative = file.text(file.required(meshes[i], field, "file"), field + ".file");
        if (index_of.count(name)) file.fail(field + ".name", "'" + name + "' names two meshes");
        // Dispatched by extension: anything but .gltf and .glb would otherwise be read as OBJ.
        if (lowercase_extension(relative) != ".obj" && !is_gltf(relative))
            file.fail(field + ".file", "'" + relative + "' is not a mesh file: expected .obj, .gltf or .glb");
        const std::string mesh_path = (directory / relative).string();
        Scene part;
        try {  // the loader names mesh_path if it is absent or not a file
            part = is_gltf(mesh_path) ? load_gltf(mesh_path) : load_obj(mesh_path);
        } catch (const InputError& e) {
            file.fail(field + ".file", e.what());
        }
        Mesh mesh = is_gltf(mesh_path) ? baked_mesh(part) : std::move(part.meshes.front());
        mesh.name = name;
        for (uint32_t& material : mesh.triangle_material) material += uint32_t(scene.materials.size());
        scene.materials.insert(scene.materials.end(), part.materials.begin(), part.materials.end());
        index_of[name] = uint32_t(scene.meshes.size());
        scene.meshes.push_back(std::move(mesh));
    }
    return index_of;
}

// Row-major in the file, translation in elements 3, 7, 11; glm is column-major.
glm::mat4 parse_transform(const SceneFile& file, const json& value, const std::string& field) {
    const std::vector<double> m = file.numbers(value, field, 16);
    if (m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0)
        file.fail(field, "last row must be 0 0 0 1 (an affine transform)");
    const double determinant = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                               m[2] * (m[4] * m[9] - m[5] * m[8]);
    const auto row_length = [&](int r) { return std::hypot(m[4 * r], m[4 * r + 1], m[4 * r + 2]); };
    // Relative to the rows' scale, so that a uniformly tiny (or huge) scale is not "singular".
    if (!(std::abs(determinant) > 1e-9 * row_length(0) * row_length(1) * row_length(2)))
        file.fail(field, "is singular (its 3x3 part has determinant " + std::to_string(determinant) + ")");
    glm::mat4 transform(1.0f);
    for (int row = 0; row < 4; ++row)
        for (int col = 0; col < 4; ++col) transform[col][row] = float(m[size_t(4 * row + col)]);
    return transform;
}

void parse_instances(const SceneFile& file, const json& instances, const std::map<std::string, uint32_t>& meshes,
                     Scene& scene) {
    for (size_t i = 0; i < instances.size(); ++i) {
        const std::string field = "instances[" + std::to_string(i) + "]";
        file.expect_object(instances[i], field, {"mesh", "transform"});
        const std::string name = file.text(file.required(instances[i], field, "mesh"), field + ".mesh");
        const auto mesh = meshes.find(name);
        if (mesh == meshes.end()) file.fail(field + ".mesh", "no mesh is named '" + name + "'");
        Instance instance{mesh->second, glm::mat4(1.0f)};
        if (instances[i].contains("transform"))
            instance.transform = parse_transform(file, instances[i]["transform"], field + ".transform");
        scene.instances.push_back(instance);
    }
}

// "crytek-sponza/scene.json" is best called "crytek-sponza".
std::string scene_name(const fs::path& path) {
    const std::string stem = path.stem().string();
    const std::string folder = fs::absolute(path).parent_path().filename().string();
    return stem == "scene" && !folder.empty() ? folder : stem;
}

}  // namespace

Scene load_scene_json(const std::string& path) {
    const SceneFile file(path);
    const json root = file.parse();
    file.expect_object(root, "", {"camera", "meshes", "instances"});
    Scene scene;
    scene.name = scene_name(path);
    if (root.contains("camera")) scene.camera = parse_camera(file, root["camera"]);
    const auto meshes = load_meshes(file, file.array(file.required(root, "", "meshes"), "meshes"), scene);
    if (root.contains("instances")) {
        parse_instances(file, file.array(root["instances"], "instances"), meshes, scene);
    } else {
        for (uint32_t m = 0; m < scene.meshes.size(); ++m) scene.instances.push_back({m, glm::mat4(1.0f)});
    }
    return scene;
}

}  // namespace canopy
