#pragma once
#include "accel/bvh.h"

namespace canopy {

// Copies the tree rooted at sparse[0] into a dense array, depth first, siblings kept adjacent.
// Parallel builders reserve node slots per subtree and leave gaps; this removes them.
BvhNodes compact_sparse_nodes(const BvhNode* sparse);

}  // namespace canopy
