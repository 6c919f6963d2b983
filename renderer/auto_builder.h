#pragma once
// `--builder auto`: "model only what a scene requires". From statistics that cost one pass over the triangles,
// predict each candidate's time to image (build + frames x frame time) and take the smallest: splitting builders
// only where triangle boxes are much larger than the triangles, a two-level hierarchy only with instances.
#include "scenes/scene.h"

#include <string>
#include <vector>

namespace canopy {

struct SceneStatistics {
    uint64_t triangles = 0;         // as traced (every instance's copy)
    uint64_t unique_triangles = 0;  // as stored in meshes: what a two-level build builds
    uint64_t placements = 0;        // (instance, non-empty object) pairs: the two-level top level's size
    // Sum of triangle-box half areas over the sum of twice the triangle areas: 1 for axis-aligned right triangles,
    // large for long diagonal slivers, whose boxes spatial splits shrink (the split papers' motivation).
    double box_excess = 1.0;
    // (Sum of triangle-box half areas - sum of twice the triangle areas) over the half area of the meshes' bounds:
    // by Crofton's formula, how many more triangle boxes than triangles a random ray through the scene pierces, an
    // upper bound on the tests per ray that splitting triangles can save.
    double reducible_cover = 0.0;
    // The camera's eye inside the scene's bounds: a room seen from within, where paths bounce to the bounce limit
    // (crytek-sponza, sibenik, conference: 8.3 to 9 rays a pixel), not an object seen from outside (1.2 to 5.4).
    bool camera_inside = false;
};

SceneStatistics scene_statistics(const Scene& scene, const FlatScene& flat);

struct AutoChoice {
    std::string builder;            // a registered builder
    std::string toplevel = "flat";  // flat, or rebraid for instanced scenes
    std::string reason;             // one line: the statistics and predicted times that decided
};

// Picks the candidate with the least predicted time to image for `frames` frames of `pixels` pixels.
AutoChoice choose_builder(const SceneStatistics& stats, int frames, uint64_t pixels);

}  // namespace canopy
