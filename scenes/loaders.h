#pragma once
// Individual loaders behind load_scene().
#include "scenes/scene.h"

namespace canopy {

Scene load_obj(const std::string& path);         // one mesh, objects from o/g groups, Kd from .mtl
Scene load_scene_json(const std::string& path);  // ../shared/scenes/README.md format
Scene generate_scene(const std::string& spec);   // "gen:box|cylinders|surface|triangles[?tris=N&seed=S]"
Scene default_scene();                           // small, embedded, no files needed

}  // namespace canopy
