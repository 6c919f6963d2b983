#pragma once
// Node storage for parallel top-down builders. Slots are reserved by range: a subtree over n refs whose root
// sits at slot `node` keeps its 2n - 2 descendants in [descendants, descendants + 2n - 2), so no two tasks
// share slots and the tree does not depend on thread timing. finish() compacts the unused slots away.
#include "accel/bvh.h"
#include "accel/bvh_compact.h"

#include <memory>

namespace canopy {

class SparseTree {
public:
    explicit SparseTree(size_t refs)
        : nodes_(static_cast<BvhNode*>(::operator new[](sizeof(BvhNode) * (2 * std::max<size_t>(refs, 1) - 1)))) {}

    void set_leaf(uint32_t node, const BBox& bounds, uint32_t first_ref, uint32_t count) {
        nodes_.get()[node] = {bounds, first_ref, count};
    }

    // Makes `node` inner with its children at `descendants` and `descendants + 1`; returns where the left
    // and the right child's own descendants start.
    std::pair<uint32_t, uint32_t> set_inner(uint32_t node, const BBox& bounds, uint32_t descendants, uint32_t left_size) {
        nodes_.get()[node] = {bounds, descendants, 0};
        return {descendants + 2, descendants + 2 * left_size};
    }

    BvhNodes finish() const { return compact_sparse_nodes(nodes_.get()); }

private:
    struct Deleter {
        void operator()(BvhNode* p) const { ::operator delete[](p); }
    };
    std::unique_ptr<BvhNode[], Deleter> nodes_;
};

}  // namespace canopy
