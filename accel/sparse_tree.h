#pragma once
// Node storage for parallel top-down builders. Slots are reserved by range: a subtree over n refs whose root
// sits at slot `node` keeps its 2n - 2 descendants in [descendants, descendants + 2n - 2), so no two tasks
// share slots and the tree does not depend on thread timing. Subtrees built serially pack their nodes at the start
// of their range instead, and finish() compacts the unused slots away.
#include "accel/bvh.h"
#include "accel/bvh_compact.h"
#include "accel/parallel.h"

#include <memory>

namespace canopy {

class SparseTree {
public:
    explicit SparseTree(size_t refs)
        : nodes_(static_cast<BvhNode*>(::operator new[](sizeof(BvhNode) * (2 * std::max<size_t>(refs, 1) - 1)))) {}

    // Returns how far the leaf's descendants reach: it has none.
    uint32_t set_leaf(uint32_t node, const BBox& bounds, uint32_t first_ref, uint32_t count) {
        nodes_.get()[node] = {bounds, first_ref, count};
        return 0;
    }

    // Makes `node` inner with its children at `descendants` and `descendants + 1`, and builds their subtrees with
    // build_left(first) and build_right(first), which put the child's descendants from slot `first` on and return how
    // far past `first` they reach. With `work` at least `grain` the two run concurrently, each in the range reserved for
    // the left child's `left_size` refs or the rest; otherwise one after the other, the right child's descendants packed
    // after the left's, so that a serial subtree's nodes are dense and finish() reads them in order, which makes the
    // compaction several times faster (docs/results.md#builds-and-layouts). Returns how far past `descendants` this
    // node's descendants reach.
    template <class Left, class Right>
    uint32_t set_inner(uint32_t node, const BBox& bounds, uint32_t descendants, uint32_t left_size, size_t work,
                       size_t grain, Left&& build_left, Right&& build_right) {
        nodes_.get()[node] = {bounds, descendants, 0};
        if (work >= grain) {
            uint32_t right = 0;
            parallel::fork_join(work, grain, [&] { build_left(descendants + 2); },
                                [&] { right = build_right(descendants + 2 * left_size); });
            return 2 * left_size + right;
        }
        const uint32_t left = build_left(descendants + 2);
        return 2 + left + build_right(descendants + 2 + left);
    }

    BvhNodes finish() const { return compact_sparse_nodes(nodes_.get()); }

private:
    struct Deleter {
        void operator()(BvhNode* p) const { ::operator delete[](p); }
    };
    std::unique_ptr<BvhNode[], Deleter> nodes_;
};

}  // namespace canopy
