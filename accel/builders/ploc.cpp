#include "accel/builders/ploc.h"

#include "accel/cluster_tree.h"
#include "accel/morton.h"
#include "accel/parallel.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace canopy {
namespace {

constexpr size_t kGrain = 4 * 1024;

// Exclusive prefix sum of flag(i) over [0, n) into offsets (n + 1 entries), in parallel chunks.
template <class Flag>
void prefix_sum(size_t n, std::vector<uint32_t>& offsets, Flag&& flag) {
    const size_t chunks = std::max<size_t>(1, std::min<size_t>(64, n / kGrain));
    auto chunk_begin = [&](size_t c) { return n * c / chunks; };
    std::vector<uint32_t> chunk_sums(chunks + 1, 0);
    parallel::for_each(chunks, 1, [&](size_t c) {
        uint32_t sum = 0;
        for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) sum += flag(i);
        chunk_sums[c + 1] = sum;
    });
    for (size_t c = 0; c < chunks; ++c) chunk_sums[c + 1] += chunk_sums[c];
    offsets.resize(n + 1);
    parallel::for_each(chunks, 1, [&](size_t c) {
        uint32_t sum = chunk_sums[c];
        for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) {
            offsets[i] = sum;
            sum += flag(i);
        }
    });
    offsets[n] = chunk_sums[chunks];
}

class Ploc {
public:
    Ploc(const std::vector<PrimRef>& refs, uint32_t radius) : refs_(refs), tree_(refs), radius_(radius) {}

    Bvh build() {
        const MortonOrder sorted = sort_by_morton_code(refs_);
        clusters_ = sorted.order;
        const uint32_t n = uint32_t(clusters_.size());
        tree_.reserve_merges(n - 1);
        boxes_.resize(n);
        parallel::for_each(n, kGrain, [&](size_t i) { boxes_[i] = tree_.bounds(clusters_[i]); });
        while (clusters_.size() > 1) step();
        return tree_.to_bvh(refs_);
    }

private:
    // One iteration of PLOC: nearest neighbours, merging of mutual pairs, compaction.
    void step() {
        const size_t m = clusters_.size();
        neighbour_.resize(m);
        parallel::for_each(m, kGrain, [&](size_t i) { neighbour_[i] = nearest_neighbour(uint32_t(i)); });
        // The left cluster of a mutual pair makes the merge; the right one drops out.
        auto merges_here = [&](size_t i) { return uint32_t(neighbour_[neighbour_[i]] == i && i < neighbour_[i]); };
        auto survives = [&](size_t i) { return uint32_t(neighbour_[neighbour_[i]] != i || i < neighbour_[i]); };
        prefix_sum(m, merge_offsets_, merges_here);
        prefix_sum(m, survivor_offsets_, survives);
        const uint32_t first_merge = next_merge_;
        next_merge_ += merge_offsets_[m];
        next_clusters_.resize(survivor_offsets_[m]);
        next_boxes_.resize(survivor_offsets_[m]);
        parallel::for_each(m, kGrain, [&](size_t i) {
            if (!survives(i)) return;
            const uint32_t at = survivor_offsets_[i];
            if (merges_here(i)) {
                const uint32_t k = first_merge + merge_offsets_[i];
                tree_.set_merge(k, clusters_[i], clusters_[neighbour_[i]]);
                next_clusters_[at] = tree_.leaves() + k;
                next_boxes_[at] = tree_.bounds(tree_.leaves() + k);
            } else {
                next_clusters_[at] = clusters_[i];
                next_boxes_[at] = boxes_[i];
            }
        });
        clusters_.swap(next_clusters_);
        boxes_.swap(next_boxes_);
    }

    // The cluster within `radius_` positions whose merge with cluster i has the smallest area; ties broken by
    // pair_precedes, a total order on pairs, so the least pair overall is always mutual and every step merges at
    // least once. That holds where areas overflow float too (scenes beyond about 1e19): every area is then a tie.
    uint32_t nearest_neighbour(uint32_t i) const {
        const uint32_t m = uint32_t(clusters_.size());
        const uint32_t begin = i > radius_ ? i - radius_ : 0, end = std::min(m, i + radius_ + 1);
        uint32_t best = i;
        float best_area = std::numeric_limits<float>::infinity();
        for (uint32_t j = begin; j < end; ++j) {
            if (j == i) continue;
            float area = merge(boxes_[i], boxes_[j]).half_area();
            if (std::isnan(area)) area = std::numeric_limits<float>::infinity();  // an infinite extent times a zero one
            if (best == i || area < best_area || (area == best_area && pair_precedes(i, j, best))) best = j, best_area = area;
        }
        return best;
    }

    // Whether pair {i, j} comes before pair {i, k} among merges of equal area: the nearer positions first, then
    // the pair whose lower position is even, then the lower. On clusters of equal boxes (a scene of identical
    // triangles) every even position pairs with the next, halving the clusters each step; ties going to the
    // lowest position instead merged one pair per step, and a million identical triangles never finished.
    static bool pair_precedes(uint32_t i, uint32_t j, uint32_t k) {
        const uint32_t to_j = i > j ? i - j : j - i, to_k = i > k ? i - k : k - i;
        if (to_j != to_k) return to_j < to_k;
        const uint32_t low_j = std::min(i, j), low_k = std::min(i, k);
        if (low_j % 2 != low_k % 2) return low_j % 2 == 0;
        return low_j < low_k;
    }

    const std::vector<PrimRef>& refs_;
    ClusterTree tree_;
    const uint32_t radius_;
    uint32_t next_merge_ = 0;
    std::vector<uint32_t> clusters_, next_clusters_;  // cluster ids in Morton order
    std::vector<BBox> boxes_, next_boxes_;            // their bounds, beside them for the neighbour search
    std::vector<uint32_t> neighbour_, merge_offsets_, survivor_offsets_;
};

}  // namespace

// One triangle per leaf: the leaf size and costs do not enter the clustering.
Bvh build_ploc(BuildInput&& input, const BuildSettings&, uint32_t radius) {
    if (radius == 0) throw std::invalid_argument("ploc: search radius must be at least 1, got 0");
    if (input.refs.empty()) return {};
    return Ploc(input.refs, radius).build();
}

Bvh build_ploc(BuildInput&& input, const BuildSettings& settings) {
    return build_ploc(std::move(input), settings, kPlocDefaultRadius);
}

}  // namespace canopy
