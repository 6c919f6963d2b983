#pragma once
// Binned SAH object splits in SSE and AVX lanes (Wald 2007, "On fast construction of SAH-based BVHs"), shared by
// the builders that bin references by centroid: `binned` and `sbvh`. A reference's box loads straight from its
// PrimRef (lower, id, upper, tag), and lane 3 (of each half, in AVX) is ignored throughout.
#include "accel/builder.h"
#include "accel/parallel.h"

#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace canopy::sah_binning {

constexpr uint32_t kMaxBins = 32;
constexpr size_t kParallelGrain = 16 * 1024;
constexpr size_t kTwoGridsFrom = 256;  // refs binned below which one grid's set-up and merge cost more than they save

struct Box4 {
    __m128 lower, upper;

    static Box4 empty() { return {_mm_set1_ps(std::numeric_limits<float>::infinity()), _mm_set1_ps(-std::numeric_limits<float>::infinity())}; }
    static Box4 of(const PrimRef& r) { return {_mm_load_ps(&r.lower.x), _mm_load_ps(&r.upper.x)}; }
    void extend(const Box4& b) { lower = _mm_min_ps(lower, b.lower); upper = _mm_max_ps(upper, b.upper); }
    void extend(__m128 p) { lower = _mm_min_ps(lower, p); upper = _mm_max_ps(upper, p); }
    // Whether lower <= upper on x, y and z (false for an empty box).
    bool valid() const { return (_mm_movemask_ps(_mm_cmple_ps(lower, upper)) & 7) == 7; }
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

// Twice a reference's centroid (PrimRef::center2).
inline __m128 center2(const PrimRef& r) { return _mm_add_ps(_mm_load_ps(&r.lower.x), _mm_load_ps(&r.upper.x)); }

// A bin's box as (lower, -upper) in one AVX register, so that one min extends both bounds: binning then loads,
// extends and stores a bin once per axis instead of twice.
struct Box8 {
    __m256 v;

    static Box8 empty() { return {_mm256_set1_ps(std::numeric_limits<float>::infinity())}; }
    // From a PrimRef's 32 bytes (lower, id, upper, tag).
    static Box8 of(__m256 lower_upper) { return {_mm256_xor_ps(lower_upper, _mm256_setr_ps(0, 0, 0, 0, -0.0f, -0.0f, -0.0f, -0.0f))}; }
    static Box8 of(const Box4& b) { return {_mm256_set_m128(_mm_xor_ps(b.upper, _mm_set1_ps(-0.0f)), b.lower)}; }
    void extend(const Box8& b) { v = _mm256_min_ps(v, b.v); }
    __m128 lower() const { return _mm256_castps256_ps128(v); }
    __m128 negated_upper() const { return _mm256_extractf128_ps(v, 1); }
    Box4 box4() const { return {lower(), _mm_xor_ps(negated_upper(), _mm_set1_ps(-0.0f))}; }
    float half_area() const { return box4().half_area(); }
};

// Maps points of a box (doubled centroids, for object bins) to `bins` intervals per axis, the same way in binning
// and in partitioning.
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

    // Which side of the plane before bin `first_right` on `axis` a reference's centroid falls: the same answer
    // as bin3(center2(r))[axis] < first_right, in scalar float without the conversion and its round trip through
    // memory (partitioning visits every reference of every node).
    struct Plane {
        int axis;
        float origin, scale, first_right;
        bool left_of(const PrimRef& r) const {
            const float x = ((r.lower[axis] + r.upper[axis]) - origin) * scale;
            // cvttps turns NaN and x >= 2^31 into INT_MIN, which bin3 clamps to bin 0: left of any plane.
            return x < first_right || !(x < 2147483648.0f);
        }
    };
    Plane plane(int axis, uint32_t first_right) const {
        alignas(16) float o[4], s[4];
        _mm_store_ps(o, origin);
        _mm_store_ps(s, scale);
        return {axis, o[axis], s[axis], float(first_right)};
    }
};

// Bins for a node of n references: 4 + n / 20, at most max_bins (Embree's object binning uses the same count).
// Small nodes, most of a tree's, then set up, sweep and merge a few bins instead of one per reference, which makes
// builds markedly faster for the same SAH and frames (docs/results.md#builds-and-layouts).
inline uint32_t object_bin_count(uint32_t max_bins, uint32_t n) { return std::min(max_bins, 4u + n / 20); }

struct BinGrid {
    Box8 boxes[3][kMaxBins];
    uint32_t counts[3][kMaxBins];

    explicit BinGrid(uint32_t n) {
        for (int a = 0; a < 3; ++a) {
            std::fill_n(boxes[a], n, Box8::empty());
            std::fill_n(counts[a], n, 0u);
        }
    }
};

// The bins of up to kBatch consecutive refs on each axis, and their boxes as Box8.
struct BinnedBatch {
    static constexpr size_t kBatch = 16;
    alignas(16) int32_t bins[kBatch][4];
    Box8 boxes[kBatch];
    size_t count;

    BinnedBatch(const PrimRef* refs, size_t n, const BinMapping& mapping) : count(std::min(n, kBatch)) {
        for (size_t k = 0; k < count; ++k) {
            const __m256 ref = _mm256_load_ps(&refs[k].lower.x);
            const __m128 c2 = _mm_add_ps(_mm256_castps256_ps128(ref), _mm256_extractf128_ps(ref, 1));
            _mm_store_si128(reinterpret_cast<__m128i*>(bins[k]), mapping.bin3(c2));
            boxes[k] = Box8::of(ref);
        }
    }
    // Ref k into grids[k % G].
    template <size_t G>
    void add_to(BinGrid* const (&grids)[G]) const {
        for (size_t k = 0; k < count; ++k) {
            BinGrid& grid = *grids[k % G];
            for (int a = 0; a < 3; ++a) {
                grid.boxes[a][bins[k][a]].extend(boxes[k]);
                ++grid.counts[a][bins[k][a]];
            }
        }
    }
};

inline void merge_bins(BinGrid& x, const BinGrid& y, uint32_t n) {
    for (int a = 0; a < 3; ++a) {
        for (uint32_t i = 0; i < n; ++i) {
            x.boxes[a][i].extend(y.boxes[a][i]);
            x.counts[a][i] += y.counts[a][i];
        }
    }
}

// Refs [begin, end), batch by batch, ref k of a batch into grids[k % G].
template <size_t G>
void bin_batches(const PrimRef* refs, size_t begin, size_t end, const BinMapping& mapping, BinGrid* const (&grids)[G]) {
    for (size_t i = begin; i < end; i += BinnedBatch::kBatch) BinnedBatch(refs + i, end - i, mapping).add_to(grids);
}

// Bins refs [begin, begin + count) by centroid on all three axes in one pass. Refs go in batches: a batch's bins are
// all computed before any is updated, so that its refs' loads do not wait behind stores to bins whose addresses come
// late; batches of 16 binned fastest (docs/results.md#builds-and-layouts).
// Even and odd refs go to two grids, merged at the end: neighbouring refs often share a bin, and with one grid each
// would wait for the previous one's store to that bin to be forwarded.
inline BinGrid bin_refs(const PrimRef* refs, uint32_t begin, uint32_t count, const BinMapping& mapping) {
    const uint32_t n = mapping.bins;
    auto bin_chunk = [&](size_t first, size_t end) {
        BinGrid even(n);
        if (end - first < kTwoGridsFrom) {
            BinGrid* const one[] = {&even};
            bin_batches(refs, begin + first, begin + end, mapping, one);
            return even;
        }
        BinGrid odd(n);
        BinGrid* const two[] = {&even, &odd};
        bin_batches(refs, begin + first, begin + end, mapping, two);
        merge_bins(even, odd, n);
        return even;
    };
    auto join = [n](BinGrid x, const BinGrid& y) {
        merge_bins(x, y, n);
        return x;
    };
    return parallel::reduce_lazy(count, kParallelGrain, [n] { return BinGrid(n); }, bin_chunk, join);
}

struct Split {
    int axis = -1;
    uint32_t bin = 0;  // refs in bins [0, bin) go left
    float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right, half areas, T tests
    Box4 left, right;
    uint32_t left_count = 0, right_count = 0;
};

// BuildSettings::leaf_tests, the same values, for sweeps that price every bin plane: a multiply by the block's
// reciprocal instead of an integer division, exact for the power-of-two blocks that kernels use (the builders that
// sweep check the block once per build with require_power_of_two_block, not once per node here).
struct LeafTests {
    float per_block;
    explicit LeafTests(const BuildSettings& settings) : per_block(1.0f / float(settings.leaf_block)) {}
    float operator()(uint32_t count) const { return std::ceil(float(count) * per_block); }
};

inline void require_power_of_two_block(const BuildSettings& settings) {
    if (!std::has_single_bit(settings.leaf_block))
        throw std::invalid_argument("leaf_block must be a power of two, got " + std::to_string(settings.leaf_block));
}

// The SAH sweep over the bin planes of every axis; a side's cost is its area times its triangle tests. The three
// axes' sweeps go side by side, three independent chains of box unions instead of one after another, so that their
// latencies overlap (docs/results.md#builds-and-layouts). Only the winner's boxes and counts are gathered, after the
// sweep; ties go to the lower axis, then the lower plane.
inline Split best_split(const BinGrid& grid, uint32_t n, const BuildSettings& settings) {
    const LeafTests tests(settings);
    float right_cost[3][kMaxBins];  // right_cost[a][i]: bins [i, n) of axis a, negative when they are empty
    Box8 box[3];
    uint32_t count[3];
    for (int a = 0; a < 3; ++a) box[a] = grid.boxes[a][n - 1], count[a] = grid.counts[a][n - 1];
    for (uint32_t i = n - 1; i > 0; --i) {
        for (int a = 0; a < 3; ++a) {
            right_cost[a][i] = count[a] ? box[a].half_area() * tests(count[a]) : -1.0f;
            box[a].extend(grid.boxes[a][i - 1]);
            count[a] += grid.counts[a][i - 1];
        }
    }
    float cost[3][kMaxBins];  // cost[a][i]: the plane before bin i of axis a, infinite when a side is empty
    for (int a = 0; a < 3; ++a) box[a] = grid.boxes[a][0], count[a] = grid.counts[a][0];
    for (uint32_t i = 1; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            cost[a][i] = count[a] != 0 && right_cost[a][i] >= 0.0f ? box[a].half_area() * tests(count[a]) + right_cost[a][i]
                                                                   : std::numeric_limits<float>::infinity();
            box[a].extend(grid.boxes[a][i]);
            count[a] += grid.counts[a][i];
        }
    }
    Split best;
    for (int axis = 0; axis < 3; ++axis)
        for (uint32_t i = 1; i < n; ++i)
            if (cost[axis][i] < best.cost) best.axis = axis, best.bin = i, best.cost = cost[axis][i];
    if (best.axis < 0) return best;
    Box8 left = Box8::empty(), right = Box8::empty();
    for (uint32_t i = 0; i < n; ++i) {
        (i < best.bin ? left : right).extend(grid.boxes[best.axis][i]);
        (i < best.bin ? best.left_count : best.right_count) += grid.counts[best.axis][i];
    }
    best.left = left.box4();
    best.right = right.box4();
    return best;
}

}  // namespace canopy::sah_binning
