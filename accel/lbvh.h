#pragma once
#include "accel/builder.h"

namespace canopy {

// Linear BVH (Lauterbach et al. 2009) with the hierarchy emitted in parallel as Karras 2012 ("Maximizing
// Parallelism in the Construction of BVHs, Octrees, and k-d Trees") does: 63-bit Morton codes of the
// centroids, a parallel radix sort, then every inner node found independently from the sorted codes. One
// triangle per leaf, as in the quality-metrics paper. The fastest builder, with the weakest trees.
Bvh build_lbvh(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
