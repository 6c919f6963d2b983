#pragma once
#include "accel/builder.h"
#include "accel/mutable_tree.h"

namespace canopy {

// Kensler 2008, "Tree rotations for improving bounding volume hierarchies": local rotations that swap a child
// with a grandchild on the other side, or two grandchildren on opposite sides (six per node). Leaves move whole;
// to_bvh then collapses subtrees by eq. 1.

// Hill climbing: post-order passes take each node's best rotation when it lowers the SAH, until a pass finds
// none (at most kMaxHillClimbPasses). Parallel over subtrees; the same tree for any number of threads.
void hill_climb(MutableTree& tree);
Bvh build_hillclimb(BuildInput&& input, const BuildSettings& settings);

// Simulated annealing: passes with a falling temperature try one random rotation per node and accept a worse
// one with probability exp(-delta / T), then hill climbing. Random numbers are hashed from the seed, the pass
// and the node, so the tree is the same on every run and for any number of threads; it is never worse by SAH
// than hill climbing the start tree.
void anneal(MutableTree& tree, uint64_t seed);
Bvh build_anneal(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
