#pragma once
#include "accel/builder.h"

namespace canopy {

// Karras and Aila 2013, "Fast parallel construction of high-quality bounding volume hierarchies", without
// triangle splitting: bottom up over the tree, each node with at least gamma triangles roots a treelet of up to 7
// leaves (sec. 4: the largest-area leaf is expanded first), which is rebuilt optimally by dynamic programming
// over the subsets of its leaves (Algorithm 2), leaf collapse included in the cost. Three rounds with gamma = 7,
// 14, 28 (triangles below a treelet root). Parallel over disjoint subtrees; the same tree for any thread count.
void optimise_treelets(Bvh& bvh, const BuildSettings& settings);
Bvh build_treelet(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
