#pragma once
// The library's workload for `builder = "auto"`: without a camera or a renderer, candidates are timed on rays
// through the whole scene (origins uniform in its bounds, directions uniform on the sphere), closest hit.
#include "engine/auto_builder.h"
#include "kernels/ray.h"

#include <memory>
#include <vector>

namespace canopy {

// `count` rays with origins uniform in `box` and directions uniform on the sphere, fixed by `seed`.
std::vector<Ray> random_rays(const BBox& box, size_t count, uint64_t seed);

// `rays` random rays through `flat`, fixed by `seed`; the object keeps them for every candidate's sample.
std::shared_ptr<WorkloadSample> random_ray_sample(const FlatScene& flat, uint32_t rays = 1u << 18, uint64_t seed = 1);

}  // namespace canopy
