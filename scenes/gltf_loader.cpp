// glTF 2.0 loading (.gltf with embedded or external buffers, .glb). tinygltf parses the JSON and reads the
// buffers, but it does not check that an accessor stays inside its buffer, nor that an index names a vertex:
// canopy checks every byte range and index before reading, so a bad file is an error that names the file and
// the field, never a crash. Each glTF mesh placed by a node becomes one Mesh of one object; each node that
// places it, one Instance, so that two-level top levels instance what the file instances.
#include "scenes/loaders.h"

#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <numbers>
#include <numeric>
#include <sstream>

namespace canopy {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// canopy uses no textures: images are neither decoded nor required to be present.
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
    return true;
}

// tinygltf ends every message with a newline; canopy reports them on one line.
std::string one_line(const std::string& messages) {
    std::istringstream lines(messages);
    std::string joined;
    for (std::string line; std::getline(lines, line);)
        if (!line.empty()) joined += (joined.empty() ? "" : "; ") + line;
    return joined;
}

std::string indexed(const char* list, size_t index) {
    return std::string(list) + "[" + std::to_string(index) + "]";
}

// Read only once tinygltf has failed on a .gltf: its "File not found" names neither the field nor the folder.
void check_external_buffers(const std::string& path) {
    std::ifstream in(path);
    const json root = json::parse(in, nullptr, /*allow_exceptions=*/false);
    const auto buffers = root.find("buffers");
    if (buffers == root.end() || !buffers->is_array()) return;
    for (size_t i = 0; i < buffers->size(); ++i) {
        const auto uri = (*buffers)[i].find("uri");
        if (uri == (*buffers)[i].end() || !uri->is_string()) continue;
        const std::string& name = uri->get_ref<const std::string&>();
        if (name.empty() || name.starts_with("data:")) continue;
        std::error_code error;
        const fs::path file = fs::absolute(fs::path(path).parent_path() / name, error);
        if (!fs::exists(file, error))
            throw InputError(path + ": " + indexed("buffers", i) + ".uri: '" + name + "' does not exist (looked for " +
                             file.string() + ")");
    }
}

tinygltf::Model parse_gltf(const std::string& path) {
    require_regular_file(path);
    tinygltf::TinyGLTF parser;
    parser.SetImageLoader(skip_image, nullptr);
    tinygltf::Model model;
    std::string errors, warnings;
    bool parsed = false;
    const bool binary = lowercase_extension(path) == ".glb";
    try {
        parsed = binary ? parser.LoadBinaryFromFile(&model, &errors, &warnings, path)
                        : parser.LoadASCIIFromFile(&model, &errors, &warnings, path);
    } catch (const std::exception& e) {  // nlohmann's, from inside tinygltf, on some malformed values
        errors = e.what();
    }
    if (!parsed || !errors.empty()) {
        if (!binary) check_external_buffers(path);
        throw InputError(path + ": " + (errors.empty() ? std::string("tinygltf cannot read it") : one_line(errors)));
    }
    if (!warnings.empty()) std::cerr << "canopy: warning: " << path << ": " << one_line(warnings) << "\n";
    return model;
}

class GltfFile {
public:
    GltfFile(std::string path, tinygltf::Model model) : path_(std::move(path)), model_(std::move(model)) {}

    const tinygltf::Model& model() const { return model_; }

    [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
        throw InputError(path_ + ": " + field + ": " + problem);
    }

    // Entry `index` of one of the file's lists, which `field` refers to.
    template <class T>
    const T& entry(const std::vector<T>& list, int index, const std::string& field, const char* what) const {
        if (index < 0 || size_t(index) >= list.size())
            fail(field, std::string(what) + " " + std::to_string(index) + " does not exist (the file has " +
                            std::to_string(list.size()) + ")");
        return list[size_t(index)];
    }

private:
    std::string path_;
    tinygltf::Model model_;
};

// The bytes of an accessor's elements, all checked to lie inside its buffer view and buffer.
struct ElementBytes {
    const unsigned char* first = nullptr;
    size_t stride = 0;  // bytes from one element to the next
    size_t count = 0;
    const unsigned char* operator[](size_t i) const { return first + i * stride; }
};

// Whether `count` elements of `size` bytes, `stride` apart from `offset`, fit in `length` bytes; without overflow.
bool elements_fit(size_t offset, size_t stride, size_t count, size_t size, size_t length) {
    if (count == 0) return offset <= length;
    return offset <= length && size <= length - offset && count - 1 <= (length - offset - size) / stride;
}

ElementBytes accessor_bytes(const GltfFile& file, int index, const std::string& user, int type,
                            std::initializer_list<int> component_types, const std::string& expected) {
    const tinygltf::Model& model = file.model();
    const tinygltf::Accessor& accessor = file.entry(model.accessors, index, user, "accessor");
    const std::string field = indexed("accessors", size_t(index));
    if (accessor.sparse.isSparse) file.fail(field + ".sparse", "sparse accessors are not supported");
    if (accessor.type != type ||
        std::find(component_types.begin(), component_types.end(), accessor.componentType) == component_types.end())
        file.fail(field, "must hold " + expected + " for " + user);
    if (accessor.bufferView < 0) file.fail(field + ".bufferView", "missing: accessors without data are not supported");
    const tinygltf::BufferView& view =
        file.entry(model.bufferViews, accessor.bufferView, field + ".bufferView", "buffer view");
    const std::string view_field = indexed("bufferViews", size_t(accessor.bufferView));
    const tinygltf::Buffer& buffer = file.entry(model.buffers, view.buffer, view_field + ".buffer", "buffer");
    if (!elements_fit(view.byteOffset, 1, view.byteLength, 1, buffer.data.size()))
        file.fail(view_field, std::to_string(view.byteLength) + " bytes from byte " + std::to_string(view.byteOffset) +
                                  " reach beyond the " + std::to_string(buffer.data.size()) + " bytes of its buffer");
    const size_t element_size = size_t(tinygltf::GetComponentSizeInBytes(uint32_t(accessor.componentType))) *
                                size_t(tinygltf::GetNumComponentsInType(uint32_t(accessor.type)));
    const size_t stride = view.byteStride ? view.byteStride : element_size;
    if (stride < element_size)
        file.fail(view_field + ".byteStride", std::to_string(stride) + " is less than the " +
                                                  std::to_string(element_size) + " bytes of an element of " + field);
    if (!elements_fit(accessor.byteOffset, stride, accessor.count, element_size, view.byteLength))
        file.fail(field, std::to_string(accessor.count) + " elements from byte " + std::to_string(accessor.byteOffset) +
                             " reach beyond the " + std::to_string(view.byteLength) + " bytes of its buffer view");
    return {buffer.data.data() + view.byteOffset + accessor.byteOffset, stride, accessor.count};
}

std::vector<Vec3> read_positions(const GltfFile& file, int index, const std::string& user) {
    static_assert(sizeof(Vec3) == 3 * sizeof(float));
    const ElementBytes bytes =
        accessor_bytes(file, index, user, TINYGLTF_TYPE_VEC3, {TINYGLTF_COMPONENT_TYPE_FLOAT}, "float VEC3 elements");
    std::vector<Vec3> positions(bytes.count);
    for (size_t i = 0; i < bytes.count; ++i) {
        std::memcpy(&positions[i], bytes[i], sizeof(Vec3));  // memcpy: a stride need not keep floats aligned
        if (!std::isfinite(positions[i].x) || !std::isfinite(positions[i].y) || !std::isfinite(positions[i].z))
            file.fail(indexed("accessors", size_t(index)), "position " + std::to_string(i) + " is not finite");
    }
    return positions;
}

uint32_t read_unsigned(const unsigned char* bytes, int component_type) {
    if (component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) return bytes[0];
    if (component_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
        uint16_t value;
        std::memcpy(&value, bytes, sizeof value);
        return value;
    }
    uint32_t value;
    std::memcpy(&value, bytes, sizeof value);
    return value;
}

// A primitive's vertex indices: its indices accessor, or 0, 1, 2, ... when it has none.
std::vector<uint32_t> read_indices(const GltfFile& file, const tinygltf::Primitive& primitive, size_t vertex_count,
                                   const std::string& field) {
    if (primitive.indices < 0) {
        std::vector<uint32_t> in_order(vertex_count);
        std::iota(in_order.begin(), in_order.end(), 0u);
        return in_order;
    }
    const ElementBytes bytes =
        accessor_bytes(file, primitive.indices, field + ".indices", TINYGLTF_TYPE_SCALAR,
                       {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                        TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT},
                       "unsigned integer SCALAR elements");
    const int component_type = file.model().accessors[size_t(primitive.indices)].componentType;
    std::vector<uint32_t> indices(bytes.count);
    for (size_t i = 0; i < bytes.count; ++i) {
        indices[i] = read_unsigned(bytes[i], component_type);
        if (indices[i] >= vertex_count)
            file.fail(indexed("accessors", size_t(primitive.indices)),
                      "index " + std::to_string(indices[i]) + " (element " + std::to_string(i) +
                          ") is out of range: POSITION has " + std::to_string(vertex_count) + " vertices");
    }
    return indices;
}

std::string mode_name(int mode) {
    static const char* const names[] = {"POINTS",    "LINES",          "LINE_LOOP",   "LINE_STRIP",
                                        "TRIANGLES", "TRIANGLE_STRIP", "TRIANGLE_FAN"};
    return std::to_string(mode) + (mode >= 0 && mode < 7 ? std::string(" (") + names[mode] + ")" : "");
}

// A colour factor of at least 3 numbers (RGBA: the alpha is not used), none negative.
Vec3 colour(const GltfFile& file, const std::vector<double>& factor, const std::string& field) {
    if (factor.size() < 3) file.fail(field, "must have at least 3 numbers, has " + std::to_string(factor.size()));
    for (size_t i = 0; i < 3; ++i)
        if (!(factor[i] >= 0.0 && factor[i] <= double(std::numeric_limits<float>::max())))
            file.fail(field, "component " + std::to_string(i) + " must be a non-negative float, is " +
                                 std::to_string(factor[i]));
    return Vec3(float(factor[0]), float(factor[1]), float(factor[2]));
}

// emissiveFactor is at most 1; exporters (Blender's among them) write brighter lights with this extension.
float emissive_strength(const GltfFile& file, const tinygltf::Material& material, const std::string& field) {
    const auto extension = material.extensions.find("KHR_materials_emissive_strength");
    if (extension == material.extensions.end() || !extension->second.Has("emissiveStrength")) return 1.0f;
    const tinygltf::Value& strength = extension->second.Get("emissiveStrength");
    const double value = strength.IsNumber() ? strength.GetNumberAsDouble() : -1.0;
    if (!(value >= 0.0 && value <= double(std::numeric_limits<float>::max())))
        file.fail(field + ".extensions.KHR_materials_emissive_strength.emissiveStrength",
                  "must be a non-negative number");
    return float(value);
}

std::vector<Material> read_materials(const GltfFile& file) {
    std::vector<Material> materials;
    for (size_t i = 0; i < file.model().materials.size(); ++i) {
        const tinygltf::Material& m = file.model().materials[i];
        const std::string field = indexed("materials", i);
        materials.push_back(
            {m.name.empty() ? field : m.name,
             colour(file, m.pbrMetallicRoughness.baseColorFactor, field + ".pbrMetallicRoughness.baseColorFactor"),
             colour(file, m.emissiveFactor, field + ".emissiveFactor") * emissive_strength(file, m, field)});
    }
    return materials;
}

glm::dvec3 three_numbers(const GltfFile& file, const std::vector<double>& numbers, const std::string& field) {
    if (numbers.size() != 3) file.fail(field, "must have 3 numbers, has " + std::to_string(numbers.size()));
    return {numbers[0], numbers[1], numbers[2]};
}

// The node's transform relative to its parent: its matrix (column-major, as glm's), or translation x rotation x scale.
glm::dmat4 local_transform(const GltfFile& file, const tinygltf::Node& node, const std::string& field) {
    if (!node.matrix.empty()) {
        if (node.matrix.size() != 16)
            file.fail(field + ".matrix", "must have 16 numbers, has " + std::to_string(node.matrix.size()));
        return glm::make_mat4(node.matrix.data());
    }
    glm::dmat4 transform(1.0);
    if (!node.translation.empty())
        transform = glm::translate(transform, three_numbers(file, node.translation, field + ".translation"));
    if (!node.rotation.empty()) {
        const std::vector<double>& r = node.rotation;
        if (r.size() != 4)
            file.fail(field + ".rotation", "must have 4 numbers (a quaternion), has " + std::to_string(r.size()));
        const glm::dquat rotation(r[3], r[0], r[1], r[2]);  // glTF stores x, y, z, w
        if (!(glm::length(rotation) > 0.0)) file.fail(field + ".rotation", "is the zero quaternion");
        transform *= glm::mat4_cast(glm::normalize(rotation));
    }
    if (!node.scale.empty()) transform = glm::scale(transform, three_numbers(file, node.scale, field + ".scale"));
    return transform;
}

// A mesh's placement as an Instance transform: finite in float, affine and invertible, as scene.json demands.
glm::mat4 placement(const GltfFile& file, const glm::dmat4& world, const std::string& field) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!(std::abs(world[c][r]) <= double(std::numeric_limits<float>::max())))
                file.fail(field, "its world transform is not finite in float");
    if (world[0][3] != 0.0 || world[1][3] != 0.0 || world[2][3] != 0.0 || world[3][3] != 1.0)
        file.fail(field, "its world transform is not affine (last row must be 0 0 0 1)");
    const glm::dmat3 linear(world);
    const double scale = glm::length(linear[0]) * glm::length(linear[1]) * glm::length(linear[2]);
    if (!(std::abs(glm::determinant(linear)) > 1e-9 * scale)) file.fail(field, "its world transform is singular");
    return glm::mat4(world);
}

// A glTF camera looks down its node's -z with +y up.
Camera perspective_camera(const GltfFile& file, const tinygltf::Camera& gltf, const glm::dmat4& world,
                          const std::string& field) {
    const double yfov = gltf.perspective.yfov;
    if (!(yfov > 0.0 && yfov < std::numbers::pi))
        file.fail(field + ".perspective.yfov", "must be in (0, pi) radians, is " + std::to_string(yfov));
    const glm::dvec3 eye(world[3]), forward(world * glm::dvec4(0, 0, -1, 0)), up(world * glm::dvec4(0, 1, 0, 0));
    const double sideways = glm::length(glm::cross(forward, up));
    if (!(sideways > 0.0) || !std::isfinite(sideways) || !std::isfinite(glm::length(eye)))
        file.fail(field, "its node's world transform gives it no view direction and up");
    Camera camera;
    camera.eye = Vec3(eye);
    // A target as far as the eye is from the origin, so that float rounding keeps the direction at any magnitude.
    camera.target = Vec3(eye + glm::normalize(forward) * std::max(1.0, glm::length(eye)));
    camera.up = Vec3(glm::normalize(up));
    camera.fov_deg = float(yfov * 180.0 / std::numbers::pi);
    return camera;
}

// Walks the default scene's node trees, loading each mesh on first use and placing it once per node.
class SceneAssembly {
public:
    SceneAssembly(const GltfFile& file, Scene& scene)
        : file_(file),
          model_(file.model()),
          scene_(scene),
          mesh_of_gltf_mesh_(model_.meshes.size(), -1),
          reached_(model_.nodes.size(), false) {}

    void run() {
        scene_.materials = read_materials(file_);
        for (int root : root_nodes()) place_tree(root, "scene.nodes");
        if (default_material_used_) scene_.materials.push_back({"(default)", Vec3(0.8f)});
    }

private:
    struct Pending {
        int node;
        glm::dmat4 parent;
        std::string referrer;  // the field naming this node, for errors
    };

    const std::vector<int>& root_nodes() const {
        if (model_.scenes.empty()) file_.fail("scenes", "the file defines no scene, so nothing is placed");
        const int chosen = model_.defaultScene >= 0 ? model_.defaultScene : 0;
        return file_.entry(model_.scenes, chosen, "scene", "scene").nodes;
    }

    // Depth first, parents before children, without recursion: a deep hierarchy cannot overflow the stack.
    void place_tree(int root, const std::string& referrer) {
        std::vector<Pending> pending{{root, glm::dmat4(1.0), referrer}};
        while (!pending.empty()) {
            const Pending next = std::move(pending.back());
            pending.pop_back();
            const tinygltf::Node& node = file_.entry(model_.nodes, next.node, next.referrer, "node");
            const std::string field = indexed("nodes", size_t(next.node));
            // glTF nodes form disjoint trees; a node reached twice would be placed twice, or forever in a cycle.
            if (reached_[size_t(next.node)])
                file_.fail(next.referrer, "node " + std::to_string(next.node) + " has two parents (or is in a cycle)");
            reached_[size_t(next.node)] = true;
            const glm::dmat4 world = next.parent * local_transform(file_, node, field);
            if (node.mesh >= 0)
                scene_.instances.push_back({mesh_index(node.mesh, field + ".mesh"), placement(file_, world, field)});
            if (node.camera >= 0) take_camera(node.camera, world, field);
            for (size_t c = node.children.size(); c-- > 0;)
                pending.push_back({node.children[c], world, field + ".children"});
        }
    }

    void take_camera(int index, const glm::dmat4& world, const std::string& field) {
        const tinygltf::Camera& camera = file_.entry(model_.cameras, index, field + ".camera", "camera");
        if (!scene_.camera && camera.type == "perspective")
            scene_.camera = perspective_camera(file_, camera, world, indexed("cameras", size_t(index)));
    }

    uint32_t mesh_index(int gltf_mesh, const std::string& field) {
        file_.entry(model_.meshes, gltf_mesh, field, "mesh");
        int& index = mesh_of_gltf_mesh_[size_t(gltf_mesh)];
        if (index < 0) {
            index = int(scene_.meshes.size());
            scene_.meshes.push_back(load_mesh(gltf_mesh));
        }
        return uint32_t(index);
    }

    Mesh load_mesh(int index) {
        const tinygltf::Mesh& gltf = model_.meshes[size_t(index)];
        const std::string field = indexed("meshes", size_t(index));
        Mesh mesh;
        mesh.name = gltf.name.empty() ? field : gltf.name;
        for (size_t p = 0; p < gltf.primitives.size(); ++p)
            add_primitive(gltf.primitives[p], field + indexed(".primitives", p), mesh);
        mesh.objects = {{mesh.name, 0, uint32_t(mesh.triangles.size())}};
        return mesh;
    }

    void add_primitive(const tinygltf::Primitive& primitive, const std::string& field, Mesh& mesh) {
        if (primitive.mode != TINYGLTF_MODE_TRIANGLES)
            file_.fail(field + ".mode",
                       mode_name(primitive.mode) + " is not supported: canopy reads TRIANGLES (4) only");
        const auto position = primitive.attributes.find("POSITION");
        if (position == primitive.attributes.end()) file_.fail(field + ".attributes", "has no POSITION");
        const std::vector<Vec3> positions = read_positions(file_, position->second, field + ".attributes.POSITION");
        const std::vector<uint32_t> indices = read_indices(file_, primitive, positions.size(), field);
        if (indices.size() % 3 != 0)
            file_.fail(field, std::to_string(indices.size()) + " vertex indices do not make whole triangles");
        const auto base = uint32_t(mesh.positions.size());
        mesh.positions.insert(mesh.positions.end(), positions.begin(), positions.end());
        for (size_t i = 0; i < indices.size(); i += 3)
            mesh.triangles.emplace_back(base + indices[i], base + indices[i + 1], base + indices[i + 2]);
        if (primitive.material >= 0) file_.entry(model_.materials, primitive.material, field + ".material", "material");
        // As for an OBJ without a .mtl, a file without materials leaves the meshes without per-triangle materials.
        if (!model_.materials.empty())
            mesh.triangle_material.insert(mesh.triangle_material.end(), indices.size() / 3, material_of(primitive));
    }

    // A primitive without a material gets canopy's default grey (glTF's default is white), as an OBJ face without
    // usemtl.
    uint32_t material_of(const tinygltf::Primitive& primitive) {
        if (primitive.material >= 0) return uint32_t(primitive.material);
        default_material_used_ = true;
        return uint32_t(model_.materials.size());
    }

    const GltfFile& file_;
    const tinygltf::Model& model_;
    Scene& scene_;
    std::vector<int> mesh_of_gltf_mesh_;  // index in scene_.meshes, -1 until a node places it
    std::vector<bool> reached_;           // per node
    bool default_material_used_ = false;
};

}  // namespace

Scene load_gltf(const std::string& path) {
    const GltfFile file(path, parse_gltf(path));
    Scene scene;
    scene.name = fs::path(path).stem().string();
    SceneAssembly(file, scene).run();
    return scene;
}

}  // namespace canopy
