#pragma once
#include "accel/builder.h"
#include "accel/wide_bvh.h"

namespace canopy {

// lbvh's wide tree emitted straight from the sorted Morton codes, with no binary tree and no collapse (the scheme
// of Embree's Morton builder). A range of sorted references is split where the highest bit differing between its
// first and last code flips (the split of Karras 2012's radix tree, sec. 4; the middle where all codes are equal).
// A wide node's children start as its whole range; the child with the most references is split in two until there
// are N or every child has at most a block's lanes, which makes it one leaf block. So children are chosen by count,
// not by surface area as the collapses choose them: the build is shorter and the frames longer (the trade is in
// docs/results.md). Widths 4 and 8. The tree is the same with any number of threads.
template <int N>
WideBvh<N> build_wide_lbvh(BuildInput&& input);

}  // namespace canopy
