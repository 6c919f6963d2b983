#pragma once
#include "accel/builder.h"

namespace canopy {

// Bittner, Hapala and Havran 2013, "Fast insertion-based optimization of bounding volume hierarchies": in
// batches of 10% of the inner nodes, those with the highest inefficiency (the paper's combined measure
// M_sum * M_min * M_area) are removed with their parents, and their two children reinserted where the SAH grows
// least (the paper's branch-and-bound search with a priority queue). Stops when the SAH fell by less than 1% over
// the last 3 batches, or after 30 batches. Serial, hence deterministic. Start tree LBVH, as in the
// quality-metrics paper.
Bvh build_bittner(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
