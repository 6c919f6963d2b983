#include "accel/builders/sweep_sah.h"

#include "accel/parallel.h"
#include "accel/sparse_tree.h"

#include <immintrin.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <span>

namespace canopy {
namespace {

constexpr size_t kParallelSubtreeGrain = 4 * 1024;
constexpr size_t kParallelSortGrain = 16 * 1024;  // smaller sorts (Bonsai's mini-trees) stay on one thread

// The box the sweep grows ref by ref, in SSE registers (lane 3 holds the refs' ids and is ignored). Its half area
// takes the same float operations in the same order as BBox::half_area, so costs are identical.
struct SweepBox {
    __m128 lower = _mm_set1_ps(std::numeric_limits<float>::infinity());
    __m128 upper = _mm_set1_ps(-std::numeric_limits<float>::infinity());

    void extend(const PrimRef& r) {
        lower = _mm_min_ps(lower, _mm_load_ps(&r.lower.x));
        upper = _mm_max_ps(upper, _mm_load_ps(&r.upper.x));
    }
    float half_area() const {
        alignas(16) float e[4];
        _mm_store_ps(e, _mm_sub_ps(upper, lower));
        return e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
    }
};

struct Split {
    int axis = -1;
    uint32_t position = 0;  // refs at [begin, position) of order[axis] go left
    float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right, half areas
};

class SweepSahBuilder {
public:
    SweepSahBuilder(std::span<const PrimRef> refs, const BuildSettings& settings, uint32_t median_depth)
        : refs_(refs), settings_(settings), max_leaf_(std::max<uint32_t>(settings.max_leaf_size, 1)),
          median_depth_(median_depth),
          scratch_(refs.size()), right_area_(refs.size()), goes_left_(refs.size()), leaf_tests_(refs.size() + 1),
          nodes_(refs.size()) {
        for (uint32_t n = 0; n < leaf_tests_.size(); ++n) leaf_tests_[n] = settings.leaf_tests(n);
        for (int axis = 0; axis < 3; ++axis) sort_by_centroid(axis);
    }

    Bvh build() {
        BBox bounds;
        for (const PrimRef& r : refs_) bounds.extend(r.bounds());
        build_subtree(0, uint32_t(refs_.size()), bounds, 0, 1, 0);
        Bvh bvh;
        bvh.refs.resize(refs_.size());
        parallel::for_each(refs_.size(), 64 * 1024, [&](size_t i) { bvh.refs[i] = refs_[order_[0][i]].prim; });
        bvh.nodes = nodes_.finish();
        return bvh;
    }

private:
    float centroid(uint32_t ref, int axis) const { return refs_[ref].lower[axis] + refs_[ref].upper[axis]; }

    // Ties are broken by index so that the order, and with it the tree, is the same on every run.
    // Keys are sorted beside their indices so that comparisons do not reach into the refs.
    void sort_by_centroid(int axis) {
        std::vector<std::pair<float, uint32_t>> keyed(refs_.size());
        for (uint32_t i = 0; i < keyed.size(); ++i) keyed[i] = {centroid(i, axis), i};
        if (keyed.size() < kParallelSortGrain) {
            std::sort(keyed.begin(), keyed.end());
        } else {
            tbb::parallel_sort(keyed.begin(), keyed.end());
        }
        std::vector<uint32_t>& order = order_[axis];
        order.resize(refs_.size());
        for (uint32_t i = 0; i < order.size(); ++i) order[i] = keyed[i].second;
    }

    // The sweep (MacDonald and Booth, sec. 3): right-to-left areas first, then left to right.
    Split best_split(uint32_t begin, uint32_t end) {
        Split best;
        for (int axis = 0; axis < 3; ++axis) {
            const std::vector<uint32_t>& order = order_[axis];
            SweepBox right;
            for (uint32_t i = end; i-- > begin + 1;) {
                right.extend(refs_[order[i]]);
                right_area_[i] = right.half_area() * leaf_tests_[end - i];
            }
            SweepBox left;
            for (uint32_t i = begin + 1; i < end; ++i) {
                left.extend(refs_[order[i - 1]]);
                const float cost = left.half_area() * leaf_tests_[i - begin] + right_area_[i];
                if (cost < best.cost) best = {axis, i, cost};
            }
        }
        return best;
    }

    // Returns how far past `descendants` its descendants reach (SparseTree::set_inner).
    uint32_t build_subtree(uint32_t begin, uint32_t end, const BBox& bounds, uint32_t node, uint32_t descendants,
                           uint32_t depth) {
        const uint32_t n = end - begin;
        if (n == 1) return nodes_.set_leaf(node, bounds, begin, n);
        Split split;
        if (depth < median_depth_) {
            split = best_split(begin, end);
            const float area = bounds.half_area();
            const float split_cost = settings_.costs.inner * area + settings_.costs.triangle * split.cost;
            if (n <= max_leaf_ && settings_.costs.triangle * settings_.leaf_tests(n) * area <= split_cost)
                return nodes_.set_leaf(node, bounds, begin, n);
        } else if (n <= max_leaf_) {
            return nodes_.set_leaf(node, bounds, begin, n);
        }
        // Too deep, or no finite cost (box areas that overflow float, scenes beyond about 1e19): cut at the median.
        if (split.axis < 0) split = {bounds.largest_axis(), begin + n / 2, 0.0f};
        partition(begin, end, split);
        const BBox left = bounds_of(begin, split.position), right = bounds_of(split.position, end);
        return nodes_.set_inner(
            node, bounds, descendants, split.position - begin, n, kParallelSubtreeGrain,
            [&](uint32_t first) { return build_subtree(begin, split.position, left, descendants, first, depth + 1); },
            [&](uint32_t first) { return build_subtree(split.position, end, right, descendants + 1, first, depth + 1); });
    }

    // Splits [begin, end) of every order at the split: the other two orders are partitioned stably by which
    // side each ref went to, so each keeps its sort within both children.
    void partition(uint32_t begin, uint32_t end, const Split& split) {
        const std::vector<uint32_t>& chosen = order_[split.axis];
        for (uint32_t i = begin; i < end; ++i) goes_left_[chosen[i]] = i < split.position;
        for (int axis = 0; axis < 3; ++axis) {
            if (axis == split.axis) continue;
            std::vector<uint32_t>& order = order_[axis];
            uint32_t left = begin, right = split.position;
            for (uint32_t i = begin; i < end; ++i) scratch_[goes_left_[order[i]] ? left++ : right++] = order[i];
            std::copy(scratch_.begin() + begin, scratch_.begin() + end, order.begin() + begin);
        }
    }

    BBox bounds_of(uint32_t begin, uint32_t end) const {
        BBox b;
        for (uint32_t i = begin; i < end; ++i) b.extend(refs_[order_[0][i]].bounds());
        return b;
    }

    std::span<const PrimRef> refs_;
    const BuildSettings& settings_;
    const uint32_t max_leaf_;
    const uint32_t median_depth_;  // depth from which nodes are cut at the median
    std::array<std::vector<uint32_t>, 3> order_;
    std::vector<uint32_t> scratch_;    // by position: subtrees use disjoint ranges
    std::vector<float> right_area_;    // by position
    std::vector<uint8_t> goes_left_;   // by ref: subtrees hold disjoint refs
    std::vector<float> leaf_tests_;    // settings.leaf_tests(n) by n: the sweep asks for every n
    SparseTree nodes_;
};

}  // namespace

Bvh build_sweep_sah(BuildInput&& input, const BuildSettings& settings) {
    if (input.refs.empty()) return {};
    return SweepSahBuilder(input.refs, settings, kMedianFallbackDepth).build();
}

Bvh build_sweep_sah_subtree(std::span<const PrimRef> refs, const BuildSettings& settings, uint32_t median_depth) {
    if (refs.empty()) return {};
    return SweepSahBuilder(refs, settings, median_depth).build();
}

}  // namespace canopy
