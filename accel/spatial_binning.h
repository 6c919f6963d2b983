#pragma once
// SBVH's spatial binning (Stich, Friedrich and Dietrich 2009, sec. 4.2): a node's references chopped into the
// bins of an axis, each bin's box the union of the parts of the triangles inside it. The boxes only price splits
// (the split itself clips exactly, accel/triangle_clipping.h), so the chopping is computed in float, within a few
// ulps of the exact parts (tests/test_clipping.cpp).
#include "accel/sah_binning.h"

#include <algorithm>
#include <array>
#include <limits>

namespace canopy::spatial_binning {

using sah_binning::Box4;

constexpr uint32_t kMaxBins = 12;

// Maps a coordinate to one of `bins` intervals over [lower, upper] of one axis, the same way everywhere.
struct AxisBins {
    float origin = 0, scale = 0, width = 0;
    uint32_t bins = 1;

    AxisBins(float lower, float upper, uint32_t n)
        : origin(lower), scale(upper > lower ? float(n) * 0.99999f / (upper - lower) : 0.0f),
          width((upper - lower) / float(n)), bins(n) {}
    uint32_t bin(float x) const { return std::min(uint32_t(std::max((x - origin) * scale, 0.0f)), bins - 1); }
    float plane(uint32_t i) const { return origin + float(i) * width; }
};

// One axis's spatial bins: each bin's box and how many references enter (start in) and leave (end in) it.
struct SpatialAxis {
    std::array<sah_binning::Box8, kMaxBins> bounds;
    std::array<uint32_t, kMaxBins> entries{}, exits{};

    SpatialAxis() { bounds.fill(sah_binning::Box8::empty()); }
    void add(const SpatialAxis& o) {
        for (uint32_t i = 0; i < kMaxBins; ++i) {
            bounds[i].extend(o.bounds[i]);
            entries[i] += o.entries[i];
            exits[i] += o.exits[i];
        }
    }
};

inline __m128 load_point(const Vec3& p) { return _mm_setr_ps(p.x, p.y, p.z, 0.0f); }

// Where edge a-b crosses the plane at `position` on `axis` (lane mask `on_axis`), in float, given the reciprocal
// of the edge's length on the axis. The edge's parameter is clamped to [0, 1], so a plane that rounding puts just
// outside the edge gives an end point, as does a zero length (an infinite or NaN parameter).
inline __m128 edge_crossing(__m128 a, __m128 b, float a_axis, float inv_length, float position, __m128 on_axis) {
    const float t = (position - a_axis) * inv_length;
    const float s = t > 0.0f ? (t < 1.0f ? t : 1.0f) : 0.0f;
    const __m128 p = _mm_add_ps(a, _mm_mul_ps(_mm_set1_ps(s), _mm_sub_ps(b, a)));
    return _mm_blendv_ps(p, _mm_set1_ps(position), on_axis);
}

// The part of `triangle` in each of bins first..last of `map` (first < last), clipped to `piece`, handed to
// part(k, box) where it is not empty. A part's box is that of the triangle's vertices between the bin's planes
// (the first bin reaching down and the last up without limit: the clip trims them) and of the crossings of its
// edges with those planes. Each plane is crossed by the edge from the lowest to the highest vertex and by one of
// the other two, and its crossings serve the bins on both sides: the triangle is not clipped at every plane in
// turn, as Stich et al. describe it.
template <class Part>
void chop(const Triangle& triangle, const Box4& piece, int axis, const AxisBins& map, uint32_t first, uint32_t last,
          Part&& part) {
    struct Vertex {
        __m128 p;
        float c;  // coordinate on the axis
    };
    Vertex v[3] = {{load_point(triangle.v0), triangle.v0[axis]}, {load_point(triangle.v1), triangle.v1[axis]},
                   {load_point(triangle.v2), triangle.v2[axis]}};
    if (v[1].c < v[0].c) std::swap(v[0], v[1]);
    if (v[2].c < v[1].c) std::swap(v[1], v[2]);
    if (v[1].c < v[0].c) std::swap(v[0], v[1]);
    // The edges' reciprocal lengths on the axis, in one division: v0-v2, v0-v1, v1-v2.
    alignas(16) float inv[4];
    _mm_store_ps(inv, _mm_div_ps(_mm_set1_ps(1.0f), _mm_setr_ps(v[2].c - v[0].c, v[1].c - v[0].c, v[2].c - v[1].c, 1.0f)));
    alignas(16) int32_t lanes[4] = {0, 0, 0, 0};
    lanes[axis] = -1;
    const __m128 on_axis = _mm_load_ps(reinterpret_cast<const float*>(lanes));
    Box4 box = Box4::empty();  // the crossings of the bin's lower plane
    for (uint32_t k = first;; ++k) {
        const float below = k == first ? -std::numeric_limits<float>::infinity() : map.plane(k);
        const float above = k == last ? std::numeric_limits<float>::infinity() : map.plane(k + 1);
        for (const Vertex& vertex : v)
            if (vertex.c >= below && vertex.c <= above) box.extend(vertex.p);
        Box4 next = Box4::empty();
        if (k < last) {
            const bool low = above < v[1].c;  // the plane crosses v0-v1, else v1-v2
            next.extend(edge_crossing(v[0].p, v[2].p, v[0].c, inv[0], above, on_axis));
            next.extend(edge_crossing(v[1].p, low ? v[0].p : v[2].p, v[1].c, low ? -inv[1] : inv[2], above, on_axis));
            box.extend(next);
        }
        box = {_mm_max_ps(box.lower, piece.lower), _mm_min_ps(box.upper, piece.upper)};
        if (box.valid()) part(k, box);
        if (k == last) break;
        box = next;
    }
}

// Stich et al.'s binning of a reference that spans bins first..last: its triangle's part in each extends that
// bin, and it counts as entering the first and leaving the last.
inline void bin_chopped(const Triangle& triangle, const Box4& piece, int axis, const AxisBins& map, uint32_t first,
                        uint32_t last, SpatialAxis& out) {
    chop(triangle, piece, axis, map, first, last, [&](uint32_t k, const Box4& box) { out.bounds[k].extend(sah_binning::Box8::of(box)); });
    ++out.entries[first];
    ++out.exits[last];
}

}  // namespace canopy::spatial_binning
