#pragma once
#include "accel/builder.h"

namespace canopy {

// Parallel locally-ordered clustering (Meister and Bittner 2018, "Parallel Locally-Ordered Clustering for
// Bounding Volume Hierarchy Construction"): clusters in Morton order each find their nearest neighbour, by
// the surface area of the merged box, among the `radius` clusters on either side; mutual nearest neighbours
// merge; the array is compacted; repeat until one cluster is left. One triangle per leaf.
constexpr uint32_t kPlocDefaultRadius = 16;

Bvh build_ploc(BuildInput&& input, const BuildSettings& settings);
// The same with another search radius (>= 1; std::invalid_argument otherwise).
Bvh build_ploc(BuildInput&& input, const BuildSettings& settings, uint32_t radius);

}  // namespace canopy
