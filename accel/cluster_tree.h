#pragma once
// The tree that bottom-up (agglomerative) builders produce, and its conversion into a Bvh. Clustering merges
// two clusters at a time, so the result has one triangle per leaf, as in the quality-metrics paper.
#include "accel/bvh.h"

#include <array>
#include <vector>

namespace canopy {

// Clusters 0 .. n - 1 are the leaves (cluster i is refs[i]); cluster n + k is the k-th merge, of two earlier
// clusters; the last cluster is the root.
class ClusterTree {
public:
    explicit ClusterTree(const std::vector<PrimRef>& refs);

    uint32_t leaves() const { return leaves_; }
    const BBox& bounds(uint32_t cluster) const { return bounds_[cluster]; }
    // Appends the merge of clusters a and b; returns its id.
    uint32_t merge(uint32_t a, uint32_t b);
    // Pre-sized form for parallel builders: merge k (id n + k) of a and b, written by exactly one task.
    void set_merge(uint32_t k, uint32_t a, uint32_t b);
    void reserve_merges(uint32_t merges);

    // Lays the tree out depth first (siblings adjacent, leaves' refs in visiting order). Merge chains can be
    // far deeper than kMaxBvhDepth: a subtree that would reach past it from kMedianFallbackDepth down is
    // rebuilt there by median splits of its triangles' centroids, which adds at most 32 levels.
    Bvh to_bvh(const std::vector<PrimRef>& refs) const;

private:
    uint32_t leaves_;
    std::vector<BBox> bounds_;                         // by cluster
    std::vector<std::array<uint32_t, 2>> children_;    // by merge
};

}  // namespace canopy
