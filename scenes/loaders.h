#pragma once
// Individual loaders behind load_scene().
#include "scenes/scene.h"

namespace canopy {

Scene load_obj(const std::string& path);         // one mesh, objects from o/g groups, Kd and Ke from .mtl
// .gltf or .glb: a mesh per glTF mesh, an instance per node placing one, the first perspective camera,
// baseColorFactor and emissiveFactor as materials.
Scene load_gltf(const std::string& path);
Scene load_scene_json(const std::string& path);  // ../shared/scenes/README.md format
Scene generate_scene(const std::string& spec);   // "gen:box|city|cylinders|foliage|mirror|room|surface|triangles[?tris=N&seed=S]"
// The most vertices and triangles generate_scene(spec) makes, from the spec alone; throws InputError for a bad spec.
SceneSize generated_scene_size(const std::string& spec);
Scene default_scene();                           // small, embedded, no files needed

std::string lowercase_extension(const std::string& path);  // ".obj" for "a/B.OBJ"
bool is_gltf(const std::string& path);                     // by its extension, .gltf or .glb
// Throws InputError naming `path` and what it is when it is not a regular file: absent, a folder, a FIFO, ...
void require_regular_file(const std::string& path);

// Every instance's objects transformed into one mesh: how a scene.json places a whole glTF file, node
// hierarchy and all, as one of its meshes. Its meshes have per-triangle materials all or none, as loaders make them.
Mesh baked_mesh(const Scene& scene);

}  // namespace canopy
