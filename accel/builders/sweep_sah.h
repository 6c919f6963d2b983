#pragma once
#include "accel/builder.h"

#include <span>

namespace canopy {

// Full sweep SAH (MacDonald and Booth 1990; "BBVH" in the quality-metrics paper): at every node the refs
// are swept in centroid order along each axis and the cheapest of all n - 1 splits per axis is taken; a
// leaf is made where eq. 1's local cost of a leaf is no more than the split's. The three centroid orders
// are sorted once and kept by stable partitioning, so each level costs O(n). Parallel over subtrees; the
// tree does not depend on the number of threads.
Bvh build_sweep_sah(BuildInput&& input, const BuildSettings& settings);

// The same sweep over `refs` alone, for builders that assemble trees from parts (Bonsai's mini-trees and top
// tree): leaves hold the refs' `prim` fields, and nodes at `median_depth` or deeper are cut at the median, so
// the subtree is at most median_depth + ceil(log2(refs.size())) deep.
Bvh build_sweep_sah_subtree(std::span<const PrimRef> refs, const BuildSettings& settings, uint32_t median_depth);

}  // namespace canopy
