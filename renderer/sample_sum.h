#pragma once
// An image of many samples whose bits do not depend on how its samples were split between processes: the
// samples are summed in one fixed pairwise tree over their indices, whichever rank rendered them.
#include "renderer/frames.h"
#include "renderer/image.h"

#include <cstdint>
#include <functional>
#include <vector>

namespace canopy {

// Sums per-sample images in the fixed binary tree over sample indices [0, count): a node covering samples
// [first, first + 2^level) sums its left child and then its right one, or is its left child when the right
// one holds no sample. Subtrees (single samples, or sums of whole subtrees) are pushed in order of their
// first sample; pushing a subtree's sum gives the bits of pushing its samples, so any split of [0, count)
// into runs, each run summed by its own instance, gives the same root. Pairwise summation also keeps the
// rounding error growing with log2(count) rather than count. Holds at most log2(count) + 1 images.
class PairwiseImageSum {
public:
    explicit PairwiseImageSum(uint32_t count) : count_(count) {}
    void push(uint32_t first, uint32_t level, Image sum);
    // The subtrees held, in order: after every sample of a run was pushed, the run's whole contribution.
    struct Node {
        uint32_t first, level;
        Image sum;
    };
    std::vector<Node> take_nodes() && { return std::move(nodes_); }
    // The sum of all `count` samples; throws std::logic_error when some were not pushed.
    Image root() &&;

private:
    uint32_t count_;
    std::vector<Node> nodes_;  // a stack: the last is the latest subtree
};

struct SampledImage {
    Image sums;     // rank 0: every sample's radiance summed per pixel; other ranks: empty
    uint64_t rays;  // rank 0: the rays of every rank
};

// Renders the frames first_frame + s for s in [0, spp), each rank of the job (distributed.h) a contiguous
// share of them, and sums them on rank 0 by PairwiseImageSum: the same image bit for bit from any number of
// ranks. `progress` (rank 0's share done, in [0, 1]) is called on rank 0 only. Collective.
SampledImage render_samples(const Accelerator& accel, const ShadingScene& shading, const PinholeCamera& camera,
                            uint32_t first_frame, int spp, const std::function<void(float)>& progress = {});

}  // namespace canopy
