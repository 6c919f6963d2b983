#pragma once
// Dynamic-in-static scenes (Benthin et al. 2017, sec. 6.3 and Table 3): one placed object moves rigidly every
// frame among static ones. It turns about a vertical axis beside it, like a carousel horse: its centre drives
// round a closed circle while the object turns with it, and both stay inside the scene's bounds.
#include "renderer/frames.h"

#include <string>
#include <vector>

namespace canopy {

// A turn takes this many frames; frame 0 and every multiple of it show the object at rest.
constexpr uint32_t kFramesPerTurn = 32;

struct DynamicObject {
    uint32_t placement = 0;  // index into two_level_input(scene).instances
    std::string name;        // the object's (OBJ group's) name, or its mesh's when the group has none
    glm::mat4 rest{1.0f};    // its placement at frame 0
    std::vector<Triangle> triangles;  // object space
    uint32_t first_triangle = 0;      // its triangles in the flat scene
    Vec3 pivot{0.0f};                 // a point on the vertical axis it turns about
    int up_axis = 1;                  // that axis: the world axis nearest the camera's up
    float path_radius = 0.0f;         // from that axis to the centre of the object's bounds
};

// `spec`: "auto", a placement index, or the name of an object (OBJ group) or mesh, meaning its first placement.
// auto takes the placement with the most triangles among those that span at most a quarter of the scene's
// diagonal (a character among the static scene, like the paper's robot), or the largest placement if none is
// that small. Throws std::invalid_argument naming --dynamic for an unknown name, an index out of range, or an
// object without triangles.
DynamicObject choose_dynamic_object(const Scene& scene, const FlatScene& flat, const std::string& spec);

// The object's placement at `frame`: its rest placement followed by a rotation about the pivot axis by
// frame / kFramesPerTurn of a turn. The path radius is the object's horizontal diameter, or less where the
// object's horizontal bounding circle would leave the scene's bounds (0 when even the circle at rest does not fit).
glm::mat4 dynamic_placement(const DynamicObject& object, uint32_t frame);

// Writes the object's world triangles under `to_world` into the flat scene, computed as flatten() computes them.
void place_dynamic_object(const DynamicObject& object, const glm::mat4& to_world, FlatScene& flat);

// Places the object for `frame` in the flat scene and says so as a move for the accelerators.
PlacementMove move_dynamic_object(const DynamicObject& object, uint32_t frame, FlatScene& flat);

}  // namespace canopy
