#pragma once
#include "accel/builder.h"

namespace canopy {

// Linear BVH (Lauterbach et al. 2009): 63-bit Morton codes of the centroids, a parallel radix sort, then the
// binary radix tree of Karras 2012 ("Maximizing Parallelism in the Construction of BVHs, Octrees, and k-d
// Trees") over the sorted codes, emitted with its bounds in one parallel bottom-up pass (Apetrei 2014). One
// triangle per leaf, as in the quality-metrics paper. The fastest builder, with the weakest trees.
Bvh build_lbvh(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
