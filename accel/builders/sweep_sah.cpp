#include "accel/builders/sweep_sah.h"

#include "accel/parallel.h"
#include "accel/top_down_builder.h"

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

// The full sweep (MacDonald and Booth, sec. 3) over three centroid orders kept by stable partitioning, for
// TopDownBuilder.
class SweepSahSearch {
public:
    struct Node {
        uint32_t begin, end;  // positions in every order
        BBox bounds;
    };
    struct Split {
        int axis = -1;
        uint32_t position = 0;  // refs at [begin, position) of order[axis] go left
        float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right, half areas
        bool found() const { return axis >= 0; }
    };
    using Children = std::pair<Node, Node>;

    SweepSahSearch(std::span<const PrimRef> refs, const BuildSettings& settings)
        : refs_(refs), scratch_(refs.size()), right_area_(refs.size()), goes_left_(refs.size()),
          leaf_tests_(refs.size() + 1) {
        for (uint32_t n = 0; n < leaf_tests_.size(); ++n) leaf_tests_[n] = settings.leaf_tests(n);
        for (int axis = 0; axis < 3; ++axis) sort_by_centroid(axis);
    }

    Node root() const {
        BBox bounds;
        for (const PrimRef& r : refs_) bounds.extend(r.bounds());
        return {0, uint32_t(refs_.size()), bounds};
    }
    // The prim of the ref at `position` once the tree is built: leaves index the first order.
    uint32_t prim_at(size_t position) const { return refs_[order_[0][position]].prim; }

    void prepare(Node&) const {}
    static uint32_t count(const Node& node) { return node.end - node.begin; }
    static uint32_t first(const Node& node) { return node.begin; }
    static uint32_t slots(const Node& node) { return count(node); }
    static BBox box(const Node& node) { return node.bounds; }
    static float half_area(const Node& node) { return node.bounds.half_area(); }
    static bool leaf_without_search(const Node&) { return false; }

    // Right-to-left areas first, then left to right. No finite cost (box areas that overflow float, scenes
    // beyond about 1e19) finds no split; nor does a box of no area (a line, a point, or a scene near 1e-20 whose
    // areas underflow), where every cost is 0 and the first split, one reference against the rest, would win.
    Split find(const Node& node) {
        Split best;
        if (!(node.bounds.half_area() > 0.0f)) return best;
        for (int axis = 0; axis < 3; ++axis) {
            const std::vector<uint32_t>& order = order_[axis];
            SweepBox right;
            for (uint32_t i = node.end; i-- > node.begin + 1;) {
                right.extend(refs_[order[i]]);
                right_area_[i] = right.half_area() * leaf_tests_[node.end - i];
            }
            SweepBox left;
            for (uint32_t i = node.begin + 1; i < node.end; ++i) {
                left.extend(refs_[order[i - 1]]);
                const float cost = left.half_area() * leaf_tests_[i - node.begin] + right_area_[i];
                if (cost < best.cost) best = {axis, i, cost};
            }
        }
        return best;
    }

    std::optional<Children> split(const Node& node, const Split& chosen) {
        partition(node.begin, node.end, chosen);
        return Children{{node.begin, chosen.position, bounds_of(node.begin, chosen.position)},
                        {chosen.position, node.end, bounds_of(chosen.position, node.end)}};
    }

    // Too deep, or no split found: the middle of the order on the node's largest axis.
    Children median(const Node& node) {
        return *split(node, {node.bounds.largest_axis(), node.begin + count(node) / 2, 0.0f});
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
    std::array<std::vector<uint32_t>, 3> order_;
    std::vector<uint32_t> scratch_;    // by position: subtrees use disjoint ranges
    std::vector<float> right_area_;    // by position
    std::vector<uint8_t> goes_left_;   // by ref: subtrees hold disjoint refs
    std::vector<float> leaf_tests_;    // settings.leaf_tests(n) by n: the sweep asks for every n
};

Bvh sweep_tree(std::span<const PrimRef> refs, const BuildSettings& settings, uint32_t median_depth) {
    SweepSahSearch search(refs, settings);
    const TopDownLimits limits{std::max<uint32_t>(settings.max_leaf_size, 1), median_depth, kParallelSubtreeGrain};
    TopDownBuilder<SweepSahSearch> builder(search, settings, limits, refs.size());
    Bvh bvh;
    bvh.nodes = builder.build(search.root());
    bvh.refs.resize(refs.size());
    parallel::for_each(refs.size(), 64 * 1024, [&](size_t i) { bvh.refs[i] = search.prim_at(i); });
    return bvh;
}

}  // namespace

Bvh build_sweep_sah(BuildInput&& input, const BuildSettings& settings) {
    if (input.refs.empty()) return {};
    return sweep_tree(input.refs, settings, kMedianFallbackDepth);
}

Bvh build_sweep_sah_subtree(std::span<const PrimRef> refs, const BuildSettings& settings, uint32_t median_depth) {
    if (refs.empty()) return {};
    return sweep_tree(refs, settings, median_depth);
}

}  // namespace canopy
