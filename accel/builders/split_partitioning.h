#pragma once
// The partitioning stage of Bonsai (Ganestam et al. 2015) and its SAH-guided split variant (Ganestam and Doggett
// 2016, sec. 3.2 and 4.1): the refs are cut recursively at the spatial median of their mid-point bounds into
// partitions of at most a threshold size, each the input of one mini-tree. With splitting, every cut also clips
// the triangles that straddle the plane and keeps the halves where that lowers the cut's SAH cost. The refs grow
// in place: each partition keeps free space behind it, shared out by size, and a right side that outgrows it
// moves to a new region with 20% padding.
#include "base/geometry.h"

#include <memory>
#include <span>
#include <vector>

namespace canopy {

// Sec. 3.2: 512 below 100k primitives, 8192 above 4M, linear in between.
uint32_t split_partition_threshold(size_t primitives);

struct Partitioning {
    std::vector<std::span<PrimRef>> partitions;    // left to right; each at most the threshold unless uncuttable
    uint64_t reference_capacity = 0;               // PrimRef slots allocated in all regions
    std::vector<std::unique_ptr<PrimRef[]>> regions;  // owns the memory the partitions point into

    size_t reference_count() const;
};

// Split partitioning allocates at most this many PrimRef slots per input ref, the root's 20% padding included: a
// split whose halves would need more (a moved region beyond the budget of its subtree, a share of the spare slots
// in proportion to its size) is not made. Zero-area triangles scattered in a cube reached 2.3 without it.
constexpr double kMaxReferenceCapacity = 2.0;

// Cuts `refs` into partitions of at most `threshold` refs; with `split`, SAH-guided split clipping at every cut.
// `triangles` are those the refs' `prim` fields index. Deterministic: independent of the number of threads.
Partitioning partition_refs(std::span<const Triangle> triangles, std::span<const PrimRef> refs, uint32_t threshold,
                            bool split);

// The pre-split pass on its own (SWEEPPRE, sec. 4.1): split partitioning, then compaction into one array.
std::vector<PrimRef> compact(const Partitioning& partitioning);

}  // namespace canopy
