#pragma once
// Binned SAH object splits in SSE lanes (Wald 2007, "On fast construction of SAH-based BVHs"), shared by the
// builders that bin references by centroid: `binned` and `sbvh`. A reference's box loads straight from its
// PrimRef (lower, id, upper, tag), and lane 3 is ignored throughout.
#include "accel/builder.h"
#include "accel/parallel.h"

#include <immintrin.h>

#include <limits>

namespace canopy::sah_binning {

constexpr uint32_t kMaxBins = 32;
constexpr size_t kParallelGrain = 16 * 1024;

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

struct Bin {
    Box4 bounds;
    uint32_t count;
    void add(const Bin& b) { bounds.extend(b.bounds); count += b.count; }
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

// Bins refs [begin, begin + count) by centroid on all three axes in one pass: the pass is memory bound.
inline BinGrid bin_refs(const PrimRef* refs, uint32_t begin, uint32_t count, const BinMapping& mapping) {
    const uint32_t n = mapping.bins;
    auto bin_chunk = [&](size_t first, size_t end) {
        BinGrid grid(n);
        alignas(16) int32_t b[4];
        for (size_t i = begin + first; i < begin + end; ++i) {
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
    return parallel::reduce(count, kParallelGrain, BinGrid(n), bin_chunk, join);
}

struct Split {
    int axis = -1;
    uint32_t bin = 0;  // refs in bins [0, bin) go left
    float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right, half areas, T tests
    Box4 left, right;
    uint32_t left_count = 0, right_count = 0;
};

// The SAH sweep over the bin planes of every axis; a side's cost is its area times its triangle tests.
inline Split best_split(const BinGrid& grid, uint32_t n, const BuildSettings& settings) {
    Split best;
    for (int axis = 0; axis < 3; ++axis) {
        const Bin* bins = grid.bins[axis];
        float right_cost[kMaxBins];  // right_cost[i]: bins [i, n)
        Bin right[kMaxBins];
        Bin suffix = bins[n - 1];
        for (uint32_t i = n - 1; i > 0; --i) {
            right_cost[i] = suffix.count ? suffix.bounds.half_area() * settings.leaf_tests(suffix.count) : -1.0f;
            right[i] = suffix;
            suffix.add(bins[i - 1]);
        }
        Bin prefix = bins[0];
        for (uint32_t i = 1; i < n; prefix.add(bins[i++])) {
            if (prefix.count == 0 || right_cost[i] < 0.0f) continue;
            const float cost = prefix.bounds.half_area() * settings.leaf_tests(prefix.count) + right_cost[i];
            if (cost < best.cost) best = {axis, i, cost, prefix.bounds, right[i].bounds, prefix.count, right[i].count};
        }
    }
    return best;
}

}  // namespace canopy::sah_binning
