#pragma once
#include "accel/builder.h"

namespace canopy {

// LBVH with its leaves collapsed by SAH (the option of Karras 2012 and the quality-metrics paper's LBVH
// variant): bottom-up, a subtree of n <= max_leaf_size triangles becomes one leaf when its SAH cost as a leaf,
// C_tri * leaf_tests(n) * A, is not above its cost as a subtree.
Bvh build_lbvh_sah(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
