#pragma once
// Intel Embree 3 as the reference accelerator of every benchmark: the same flat triangles, path tracer, camera and
// random numbers as canopy's rows; only the build and the traversal are Embree's.
#include "renderer/frames.h"

#include <memory>
#include <string>

namespace canopy {

// quality: "low", "medium" or "high". threads: 0 for all. Throws std::invalid_argument for another quality.
std::unique_ptr<Accelerator> make_embree_accelerator(const FlatScene& scene, const std::string& quality, int threads);
// Embree's two-level BVH: a scene per object (OBJ group), instanced by a top scene, as Embree builds instances.
std::unique_ptr<Accelerator> make_embree_two_level_accelerator(const Scene& scene, const FlatScene& flat,
                                                               const std::string& quality, int threads);

}  // namespace canopy
