#pragma once
// The loaded scene: meshes made of objects (OBJ o/g groups), instances placing meshes, a camera.
// Only positions and faces are kept: canopy loads no attribute that it does not use.
#include "base/geometry.h"

#include <glm/mat4x4.hpp>
#include <cstdint>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy {

// Every bad input (file, field, option) raises this, with a message that names the file and the
// line or field. The CLI prints it and exits non-zero.
struct InputError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

struct Camera {
    Vec3 eye{0, 0, 1};
    Vec3 target{0, 0, 0};
    Vec3 up{0, 1, 0};
    float fov_deg = 50.0f;  // vertical
};

struct Material {
    std::string name;
    Vec3 kd{0.8f};
    Vec3 emission{0.0f};  // radiance emitted (OBJ Ke, glTF emissiveFactor): an area light under --materials
};

// One OBJ o/g group; may be empty (triangle_count 0), kept so counts match the README: a two-level builder skips it.
struct Object {
    std::string name;
    uint32_t first_triangle = 0;  // range in the mesh's triangle list
    uint32_t triangle_count = 0;
};

struct Mesh {
    std::string name;
    std::vector<Vec3> positions;
    std::vector<glm::uvec3> triangles;      // indices into positions
    std::vector<uint32_t> triangle_material;  // per triangle, index into Scene::materials; empty: none
    std::vector<Object> objects;             // contiguous, covering all triangles in order; some may be empty
};

struct Instance {
    uint32_t mesh = 0;
    glm::mat4 transform{1.0f};  // glm is column-major: transform[col][row]
};

struct Scene {
    std::string name;
    std::vector<Mesh> meshes;
    std::vector<Instance> instances;  // never empty after loading: one identity instance per mesh if the file had none
    std::vector<Material> materials;
    std::optional<Camera> camera;     // absent: frame automatically (auto_camera)
};

// World-space triangle soup: every instance's triangles transformed, in instance order.
struct FlatScene {
    std::vector<Triangle> triangles;
    std::vector<uint32_t> material;  // per triangle, or empty when the scene has no materials
    std::vector<Material> materials;
    bool has_emitters = false;  // some material emits: only then does shading look emission up
    BBox bounds;
};

// Throws InputError for a scene whose coordinates are beyond 1e12 or which is less than 1e-12 across: canopy's
// single-precision intersection test hits nothing there.
FlatScene flatten(const Scene& scene);

// BENCHMARK.md: target = bounds centre, eye = centre + normalize(0, 0.35, 1) * 1.1 * |diagonal|.
Camera auto_camera(const BBox& bounds);

// The scene's own camera, or the automatic one framing its flattened triangles.
inline Camera scene_camera(const Scene& scene, const FlatScene& flat) {
    return scene.camera ? *scene.camera : auto_camera(flat.bounds);
}

// Loads a scene from a path (.json scene file or .obj) or a generator spec "gen:NAME?tris=N&seed=S".
// The empty name loads the embedded default scene.
Scene load_scene(const std::string& name);

// What is known of a scene before it is built: for a generator spec, before a triangle is generated.
struct SceneSize {
    uint64_t vertices = 0;             // stored positions, over all meshes
    uint64_t triangles = 0;            // stored triangles, over all meshes (each once, however often placed)
    uint64_t instanced_triangles = 0;  // with every placement expanded: what flatten() produces
    uint64_t instances = 1;
};

// Sees a scene's size and throws to refuse it (require_memory does, with an estimate of the build).
using SceneSizeCheck = std::function<void(const SceneSize&)>;
// load_scene, asking `fits` first: for a generator spec before any of it is generated, for a file once loaded
// (the loaders only allocate what the file's bytes hold), before instancing can multiply it.
Scene load_scene(const std::string& name, const SceneSizeCheck& fits);

SceneSize scene_size(const Scene& scene);

// Triangle count of the scene with instancing expanded.
uint64_t instanced_triangle_count(const Scene& scene);

}  // namespace canopy
