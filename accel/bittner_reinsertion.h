#pragma once
#include "accel/builder.h"

namespace canopy {

// Bittner, Hapala and Havran 2013, "Fast insertion-based optimization of bounding volume hierarchies": in
// batches, the inner nodes with the highest inefficiency (sec. 4.1: M_sum * M_min * M_area) are removed with
// their parents, and their two children reinserted where the SAH grows least (sec. 4.2-4.3: branch and bound
// over the tree with a priority queue). Stops when the SAH fell by less than 1% over the last 3 batches, or after
// kMaxBatches. Serial, hence deterministic. Start tree LBVH, as in the quality-metrics paper.
Bvh build_bittner(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
