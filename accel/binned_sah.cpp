#include "accel/binned_sah.h"

#include "accel/parallel.h"
#include "accel/sparse_tree.h"

#include <immintrin.h>

#include <array>
#include <memory>

namespace canopy {
namespace {

constexpr uint32_t kMaxBins = 32;
constexpr size_t kParallelBinningGrain = 16 * 1024;
constexpr size_t kParallelSubtreeGrain = 4 * 1024;

// A box in SSE registers; lane 3 is ignored. PrimRef's layout (lower, id, upper, tag) loads directly.
struct Box4 {
    __m128 lower, upper;

    static Box4 empty() { return {_mm_set1_ps(std::numeric_limits<float>::infinity()), _mm_set1_ps(-std::numeric_limits<float>::infinity())}; }
    static Box4 of(const PrimRef& r) { return {_mm_load_ps(&r.lower.x), _mm_load_ps(&r.upper.x)}; }
    void extend(const Box4& b) { lower = _mm_min_ps(lower, b.lower); upper = _mm_max_ps(upper, b.upper); }
    void extend(__m128 p) { lower = _mm_min_ps(lower, p); upper = _mm_max_ps(upper, p); }
    float half_area() const {
        alignas(16) float e[4];
        _mm_store_ps(e, _mm_max_ps(_mm_sub_ps(upper, lower), _mm_setzero_ps()));
        return e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
    }
    BBox bbox() const {
        alignas(16) float lo[4], hi[4];
        _mm_store_ps(lo, lower);
        _mm_store_ps(hi, upper);
        return {Vec3(lo[0], lo[1], lo[2]), Vec3(hi[0], hi[1], hi[2])};
    }
};

inline __m128 center2(const PrimRef& r) { return _mm_add_ps(_mm_load_ps(&r.lower.x), _mm_load_ps(&r.upper.x)); }

struct Bin {
    Box4 bounds;
    uint32_t count;
    void add(const Bin& b) { bounds.extend(b.bounds); count += b.count; }
};

struct Range {
    uint32_t begin, end;
    Box4 bounds, centroids;  // centroids of doubled centres (PrimRef::center2)
    uint32_t size() const { return end - begin; }
};

// Maps doubled centroids to bins, the same way in binning and in partitioning.
struct BinMapping {
    __m128 origin, scale;
    uint32_t bins;

    BinMapping(const Box4& centroids, uint32_t bin_count) : origin(centroids.lower), bins(bin_count) {
        const __m128 extent = _mm_sub_ps(centroids.upper, centroids.lower);
        const __m128 s = _mm_div_ps(_mm_set1_ps(float(bins) * 0.99999f), extent);
        scale = _mm_and_ps(s, _mm_cmpgt_ps(extent, _mm_setzero_ps()));  // flat axes map to bin 0
    }
    __m128i bin3(__m128 c2) const {
        const __m128i b = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(c2, origin), scale));
        return _mm_min_epi32(_mm_max_epi32(b, _mm_setzero_si128()), _mm_set1_epi32(int(bins) - 1));
    }
    uint32_t bin(__m128 c2, int axis) const {
        alignas(16) int32_t b[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(b), bin3(c2));
        return uint32_t(b[axis]);
    }
};

struct BinGrid {
    Bin bins[3][kMaxBins];

    explicit BinGrid(uint32_t n) {
        for (auto& axis : bins)
            for (uint32_t i = 0; i < n; ++i) axis[i] = {Box4::empty(), 0};
    }
};

BinGrid bin_refs(const PrimRef* refs, const Range& range, const BinMapping& mapping) {
    const uint32_t n = mapping.bins;
    auto bin_chunk = [&](size_t begin, size_t end) {
        BinGrid grid(n);
        alignas(16) int32_t b[4];
        for (size_t i = range.begin + begin; i < range.begin + end; ++i) {
            const Box4 box = Box4::of(refs[i]);
            _mm_store_si128(reinterpret_cast<__m128i*>(b), mapping.bin3(_mm_add_ps(box.lower, box.upper)));
            for (int a = 0; a < 3; ++a) {
                Bin& bin = grid.bins[a][b[a]];
                bin.bounds.extend(box);
                ++bin.count;
            }
        }
        return grid;
    };
    auto join = [n](BinGrid x, const BinGrid& y) {
        for (int a = 0; a < 3; ++a)
            for (uint32_t i = 0; i < n; ++i) x.bins[a][i].add(y.bins[a][i]);
        return x;
    };
    return parallel::reduce(range.size(), kParallelBinningGrain, BinGrid(n), bin_chunk, join);
}

struct Split {
    int axis = -1;
    uint32_t bin = 0;  // refs in bins [0, bin) go left
    float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right, half areas, T tests
    Box4 left, right;
};

// The SAH sweep over the bin planes of every axis; a side's cost is its area times its triangle tests.
Split best_split(const BinGrid& grid, uint32_t n, const BuildSettings& settings) {
    Split best;
    for (int axis = 0; axis < 3; ++axis) {
        const Bin* bins = grid.bins[axis];
        float right_cost[kMaxBins];  // right_cost[i]: bins [i, n)
        Box4 right_box[kMaxBins];
        Bin suffix = bins[n - 1];
        for (uint32_t i = n - 1; i > 0; --i) {
            right_cost[i] = suffix.count ? suffix.bounds.half_area() * settings.leaf_tests(suffix.count) : -1.0f;
            right_box[i] = suffix.bounds;
            suffix.add(bins[i - 1]);
        }
        Bin prefix = bins[0];
        for (uint32_t i = 1; i < n; prefix.add(bins[i++])) {
            if (prefix.count == 0 || right_cost[i] < 0.0f) continue;
            const float cost = prefix.bounds.half_area() * settings.leaf_tests(prefix.count) + right_cost[i];
            if (cost < best.cost) best = {axis, i, cost, prefix.bounds, right_box[i]};
        }
    }
    return best;
}

class BinnedSahBuilder {
public:
    BinnedSahBuilder(std::vector<PrimRef>& refs, const BuildSettings& settings)
        : refs_(refs), settings_(settings), bins_(std::clamp<uint32_t>(settings.bins, 2, kMaxBins)),
          max_leaf_(std::max<uint32_t>(settings.max_leaf_size, 1)), nodes_(refs.size()) {}

    Bvh build(const Range& root) {
        build_subtree(root, 0, 1, 0);
        Bvh bvh;
        bvh.refs.resize(refs_.size());
        parallel::for_each(refs_.size(), 64 * 1024, [&](size_t i) { bvh.refs[i] = refs_[i].prim; });
        bvh.nodes = nodes_.finish();
        return bvh;
    }

private:
    // Builds the subtree over `range` rooted at slot `node` (slots as SparseTree reserves them).
    void build_subtree(const Range& range, uint32_t node, uint32_t descendants, uint32_t depth) {
        const uint32_t n = range.size();
        if (n > 1 && depth < kMedianFallbackDepth && spread(range.centroids) > 0.0f) {
            // Fewer bins for small nodes: a bin per reference is enough, and small nodes dominate in number.
            const BinMapping mapping(range.centroids, std::min(bins_, std::max(n, 4u)));
            const Split split = best_split(bin_refs(refs_.data(), range, mapping), mapping.bins, settings_);
            const float area = range.bounds.half_area();
            const float split_cost = settings_.costs.inner * area + settings_.costs.triangle * split.cost;
            const bool leaf_is_cheaper = n <= max_leaf_ && settings_.costs.triangle * settings_.leaf_tests(n) * area <= split_cost;
            if (split.axis >= 0 && !leaf_is_cheaper) {
                partition(range, mapping, split, node, descendants, depth);
                return;
            }
        }
        if (n <= max_leaf_) {
            nodes_.set_leaf(node, range.bounds.bbox(), range.begin, n);
        } else {
            split_at_median(range, node, descendants, depth);  // coincident centroids, or too deep
        }
    }

    static float spread(const Box4& b) {
        alignas(16) float e[4];
        _mm_store_ps(e, _mm_sub_ps(b.upper, b.lower));
        return e[0] + e[1] + e[2];
    }

    // Hoare partition by bin; the children's centroid bounds are gathered on the way.
    void partition(const Range& range, const BinMapping& mapping, const Split& split, uint32_t node,
                   uint32_t descendants, uint32_t depth) {
        PrimRef* refs = refs_.data();
        uint32_t l = range.begin, r = range.end;
        Box4 left_centroids = Box4::empty(), right_centroids = Box4::empty();
        auto goes_left = [&](uint32_t i) { return mapping.bin(center2(refs[i]), split.axis) < split.bin; };
        for (;;) {
            while (l < r && goes_left(l)) left_centroids.extend(center2(refs[l++]));
            while (l < r && !goes_left(r - 1)) right_centroids.extend(center2(refs[--r]));
            if (l == r) break;
            std::swap(refs[l], refs[r - 1]);
            left_centroids.extend(center2(refs[l++]));
            right_centroids.extend(center2(refs[--r]));
        }
        emit_children({range.begin, l, split.left, left_centroids}, {l, range.end, split.right, right_centroids},
                      range, node, descendants, depth);
    }

    void split_at_median(const Range& range, uint32_t node, uint32_t descendants, uint32_t depth) {
        const uint32_t mid = range.begin + range.size() / 2;
        emit_children(bounds_of(range.begin, mid), bounds_of(mid, range.end), range, node, descendants, depth);
    }

    Range bounds_of(uint32_t begin, uint32_t end) const {
        Range r{begin, end, Box4::empty(), Box4::empty()};
        for (uint32_t i = begin; i < end; ++i) {
            r.bounds.extend(Box4::of(refs_[i]));
            r.centroids.extend(center2(refs_[i]));
        }
        return r;
    }

    void emit_children(const Range& left, const Range& right, const Range& parent, uint32_t node,
                       uint32_t descendants, uint32_t depth) {
        const auto [left_descendants, right_descendants] =
            nodes_.set_inner(node, parent.bounds.bbox(), descendants, left.size());
        parallel::fork_join(
            parent.size(), kParallelSubtreeGrain,
            [&] { build_subtree(left, descendants, left_descendants, depth + 1); },
            [&] { build_subtree(right, descendants + 1, right_descendants, depth + 1); });
    }

    std::vector<PrimRef>& refs_;
    const BuildSettings& settings_;
    const uint32_t bins_, max_leaf_;
    SparseTree nodes_;
};

}  // namespace

Bvh build_binned_sah(BuildInput&& input, const BuildSettings& settings) {
    if (input.refs.empty()) return {};
    auto bounds = [&](size_t begin, size_t end) {
        std::pair<Box4, Box4> acc{Box4::empty(), Box4::empty()};
        for (size_t i = begin; i < end; ++i) {
            acc.first.extend(Box4::of(input.refs[i]));
            acc.second.extend(center2(input.refs[i]));
        }
        return acc;
    };
    auto join = [](std::pair<Box4, Box4> a, const std::pair<Box4, Box4>& b) {
        a.first.extend(b.first);
        a.second.extend(b.second);
        return a;
    };
    const auto [box, centroids] = parallel::reduce(input.refs.size(), kParallelBinningGrain,
                                                   std::pair{Box4::empty(), Box4::empty()}, bounds, join);
    BinnedSahBuilder builder(input.refs, settings);
    return builder.build({0, uint32_t(input.refs.size()), box, centroids});
}

}  // namespace canopy
