#pragma once
#include "accel/builder.h"

namespace canopy {

// Bonsai (Ganestam et al. 2015, as summarised in sec. 2 of Ganestam and Doggett 2016): mid-point partitioning into
// mini-tree partitions, a sweep SAH mini-tree per partition built in parallel, pruning of each mini-tree's nodes
// that are large against the scene, and a sweep SAH top tree over the pruned mini-trees.
Bvh build_bonsai(BuildInput&& input, const BuildSettings& settings);

// BONSAIS (Ganestam and Doggett 2016, sec. 4.2): Bonsai with its partitioning replaced by SAH-guided split
// partitioning (sec. 3.2), so mini-trees hold clipped halves of the triangles that straddle the cuts.
Bvh build_bonsai_split(BuildInput&& input, const BuildSettings& settings);

// SWEEPPRE (sec. 5): split partitioning as a stand-alone pre-split pass, compaction (sec. 4.1), then full sweep SAH.
Bvh build_sweep_presplit(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
