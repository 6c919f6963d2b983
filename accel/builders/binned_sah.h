#pragma once
#include "accel/builder.h"

namespace canopy {

// Top-down binned SAH (Wald 2007, "On fast construction of SAH-based BVHs"): centroids binned
// into `bins` intervals per axis, the cheapest of the 3 * (bins - 1) planes taken, a leaf made where
// eq. 1's local cost of a leaf is no more than that of the split. Parallel over bins at the top and
// over subtrees below; the tree does not depend on the number of threads.
Bvh build_binned_sah(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
