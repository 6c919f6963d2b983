#pragma once
#include "accel/builder.h"

namespace canopy {

// Bottom-up agglomerative clustering (Walter, Bala, Kulkarni and Pingali 2008, "Fast agglomerative clustering
// for rendering"): repeatedly merges the closest pair of clusters, the distance being the surface area of
// their merged box, with a heap of each cluster's nearest neighbour and an auxiliary tree that finds
// neighbours in logarithmic time. One triangle per leaf, as in the quality-metrics paper's Agglo.
Bvh build_agglomerative(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
