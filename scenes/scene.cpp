// Scene dispatch by name, flattening of instances into world space, automatic framing.
#include "scenes/loaders.h"
#include "base/huge_pages.h"

#include <glm/vec4.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace canopy {
namespace {

Scene load_by_kind(const std::string& name) {
    if (name.empty()) return default_scene();
    if (name.starts_with("gen:")) return generate_scene(name);
    const std::string extension = lowercase_extension(name);
    if (extension == ".json") return load_scene_json(name);
    if (extension == ".obj") return load_obj(name);
    if (is_gltf(name)) return load_gltf(name);
    throw InputError("'" + name + "': not a scene: expected a .json, .obj, .gltf or .glb file or a gen:NAME spec");
}

std::vector<Vec3> transformed(const std::vector<Vec3>& positions, const glm::mat4& transform) {
    std::vector<Vec3> world(positions.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, positions.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) world[i] = Vec3(transform * glm::vec4(positions[i], 1.0f));
    });
    return world;
}

// Writes the mesh's triangles at `out` and returns their bounds.
BBox emit_triangles(const Mesh& mesh, const std::vector<Vec3>& world, Triangle* out) {
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, mesh.triangles.size(), 4096), BBox{},
        [&](const tbb::blocked_range<size_t>& r, BBox bounds) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                const glm::uvec3 t = mesh.triangles[i];
                out[i] = {world[t.x], world[t.y], world[t.z]};
                bounds.extend(BBox::of(out[i]));
            }
            return bounds;
        },
        merge);
}

// A mesh without per-triangle materials, in a scene where other meshes have them, gets a default material so that
// FlatScene::material covers every triangle: "(default)", added after the scene's materials when it has none.
uint32_t default_material(FlatScene& flat) {
    const auto is_default = [](const Material& m) { return m.name == "(default)"; };
    auto fallback = std::find_if(flat.materials.begin(), flat.materials.end(), is_default);
    if (fallback == flat.materials.end()) {
        flat.materials.push_back({"(default)", Vec3(0.8f)});
        fallback = flat.materials.end() - 1;
    }
    return uint32_t(fallback - flat.materials.begin());
}

// The mesh's materials at `out`, or the default material for a mesh without them.
void write_materials(const Mesh& mesh, uint32_t fallback, uint32_t* out) {
    if (mesh.triangle_material.empty()) std::fill_n(out, mesh.triangles.size(), fallback);
    else std::copy(mesh.triangle_material.begin(), mesh.triangle_material.end(), out);
}

// Where each instance's triangles start in the flat arrays, and (last) their total.
std::vector<size_t> instance_offsets(const Scene& scene) {
    std::vector<size_t> offsets(scene.instances.size() + 1, 0);
    for (size_t i = 0; i < scene.instances.size(); ++i)
        offsets[i + 1] = offsets[i] + scene.meshes.at(scene.instances[i].mesh).triangles.size();
    return offsets;
}

// The watertight test multiplies up to three vertex coordinates relative to the ray origin: past about 7e12 the
// product overflows float, and for a scene much smaller than 1e-12 it underflows; either way no ray hits anything
// (the Cornell box renders empty at scales 1e14 and 1e-16, and renders at 1e12 and 1e-14). Such a scene is
// refused rather than rendered empty.
constexpr float kMaxCoordinate = 1e12f, kMinDiagonal = 1e-12f;

std::string scientific(float x) {
    char text[32];
    std::snprintf(text, sizeof text, "%.2g", double(x));
    return text;
}

void check_representable(const std::string& name, const BBox& bounds) {
    if (bounds.empty()) return;
    const Vec3 reach = glm::max(glm::abs(bounds.lower), glm::abs(bounds.upper));
    const float largest = std::max({reach.x, reach.y, reach.z});
    if (largest > kMaxCoordinate)
        throw InputError("'" + name + "': the scene's coordinates reach " + scientific(largest) + ", beyond " +
                         scientific(kMaxCoordinate) + ", where canopy's single-precision intersection test overflows "
                         "and hits nothing; scale or move the scene towards the origin");
    const float diagonal = glm::length(bounds.extent());
    if (diagonal < kMinDiagonal)
        throw InputError("'" + name + "': the scene is " + scientific(diagonal) + " across, below " +
                         scientific(kMinDiagonal) + ", where canopy's single-precision intersection test underflows "
                         "and hits nothing; scale the scene up");
}

// In world space, placed as flatten() places it: where rays meet it.
bool has_area(const Mesh& mesh, const glm::uvec3& t, const glm::mat4& transform) {
    const auto place = [&](uint32_t v) { return Vec3(transform * glm::vec4(mesh.positions[v], 1.0f)); };
    return geometric_normal({place(t.x), place(t.y), place(t.z)}) != Vec3(0.0f);
}

// Not an error, since the file is valid, but the render would be empty sky without a word why.
void warn_if_all_zero_area(const std::string& shown_name, const Scene& scene) {
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        for (const glm::uvec3& t : mesh.triangles)
            if (has_area(mesh, t, instance.transform)) return;
    }
    std::cerr << "canopy: warning: '" << shown_name << "': all " << instanced_triangle_count(scene)
              << " triangles have zero area; no ray can hit them\n";
}

}  // namespace

std::string lowercase_extension(const std::string& path) {
    std::string extension = std::filesystem::path(path).extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return extension;
}

bool is_gltf(const std::string& path) {
    const std::string extension = lowercase_extension(path);
    return extension == ".gltf" || extension == ".glb";
}

void require_regular_file(const std::string& path) {
    namespace fs = std::filesystem;
    std::error_code error;
    const fs::file_type type = fs::status(path, error).type();
    if (type == fs::file_type::regular) return;
    if (type == fs::file_type::not_found) throw InputError(path + ": no such file");
    if (type == fs::file_type::directory) throw InputError(path + ": is a folder, not a file");
    if (error) throw InputError(path + ": cannot be examined (" + error.message() + ")");
    throw InputError(path + ": is not a regular file (a FIFO, socket or device)");
}

Mesh baked_mesh(const Scene& scene) {
    Mesh baked;
    baked.name = scene.name;
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes.at(instance.mesh);
        const auto first_vertex = uint32_t(baked.positions.size()), first_triangle = uint32_t(baked.triangles.size());
        const std::vector<Vec3> world = transformed(mesh.positions, instance.transform);
        baked.positions.insert(baked.positions.end(), world.begin(), world.end());
        for (const glm::uvec3& t : mesh.triangles) baked.triangles.push_back(t + first_vertex);
        baked.triangle_material.insert(baked.triangle_material.end(), mesh.triangle_material.begin(), mesh.triangle_material.end());
        for (const Object& object : mesh.objects)
            baked.objects.push_back({object.name, first_triangle + object.first_triangle, object.triangle_count});
    }
    return baked;
}

Scene load_scene(const std::string& name) {
    return load_scene(name, [](const SceneSize&) {});
}

Scene load_scene(const std::string& name, const SceneSizeCheck& fits) {
    if (name.starts_with("gen:")) fits(generated_scene_size(name));
    Scene scene = load_by_kind(name);
    if (!name.starts_with("gen:")) fits(scene_size(scene));
    const std::string shown_name = name.empty() ? "default scene" : name;
    if (instanced_triangle_count(scene) == 0) throw InputError("'" + shown_name + "': the scene has no triangles");
    warn_if_all_zero_area(shown_name, scene);
    return scene;
}

SceneSize scene_size(const Scene& scene) {
    SceneSize size{0, 0, instanced_triangle_count(scene), scene.instances.size()};
    for (const Mesh& mesh : scene.meshes) {
        size.vertices += mesh.positions.size();
        size.triangles += mesh.triangles.size();
    }
    return size;
}

uint64_t instanced_triangle_count(const Scene& scene) {
    uint64_t count = 0;
    for (const Instance& instance : scene.instances) count += scene.meshes.at(instance.mesh).triangles.size();
    return count;
}

// Instances are written concurrently, each at its offset: the same arrays, in instance order, as one at a time.
FlatScene flatten(const Scene& scene) {
    FlatScene flat;
    const std::vector<size_t> offsets = instance_offsets(scene);
    resize_on_huge_pages(flat.triangles, offsets.back());
    const bool with_materials = !scene.materials.empty();
    uint32_t fallback = 0;
    if (with_materials) {
        flat.materials = scene.materials;
        const bool any_without = std::any_of(scene.instances.begin(), scene.instances.end(), [&](const Instance& instance) {
            return scene.meshes[instance.mesh].triangle_material.empty();
        });
        if (any_without) fallback = default_material(flat);
        resize_on_huge_pages(flat.material, flat.triangles.size());
        flat.has_emitters = std::any_of(scene.materials.begin(), scene.materials.end(),
                                        [](const Material& m) { return m.emission != Vec3(0.0f); });
    }
    flat.bounds = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, scene.instances.size(), 1), BBox{},
        [&](const tbb::blocked_range<size_t>& r, BBox bounds) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                const Mesh& mesh = scene.meshes[scene.instances[i].mesh];
                const std::vector<Vec3> world = transformed(mesh.positions, scene.instances[i].transform);
                bounds.extend(emit_triangles(mesh, world, flat.triangles.data() + offsets[i]));
                if (with_materials) write_materials(mesh, fallback, flat.material.data() + offsets[i]);
            }
            return bounds;
        },
        merge);
    check_representable(scene.name, flat.bounds);
    return flat;
}

Camera auto_camera(const BBox& bounds) {
    Camera camera;
    camera.target = bounds.center();
    float diagonal = glm::length(bounds.extent());
    // A scene collapsed to a point (or with no bounds) still needs the eye off the target.
    if (!(diagonal > 0.0f) || !std::isfinite(diagonal)) diagonal = 1.0f;
    if (!std::isfinite(camera.target.x + camera.target.y + camera.target.z)) camera.target = Vec3(0.0f);
    camera.eye = camera.target + glm::normalize(Vec3(0.0f, 0.35f, 1.0f)) * 1.1f * diagonal;
    camera.up = Vec3(0.0f, 1.0f, 0.0f);
    camera.fov_deg = 50.0f;
    return camera;
}

}  // namespace canopy
