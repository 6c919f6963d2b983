#pragma once
#include "accel/builder.h"

namespace canopy {

// Full sweep SAH (MacDonald and Booth 1990; "BBVH" in the quality-metrics paper): at every node the refs
// are swept in centroid order along each axis and the cheapest of all n - 1 splits per axis is taken; a
// leaf is made where eq. 1's local cost of a leaf is no more than the split's. The three centroid orders
// are sorted once and kept by stable partitioning, so each level costs O(n). Parallel over subtrees; the
// tree does not depend on the number of threads.
Bvh build_sweep_sah(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
