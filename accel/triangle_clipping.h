#pragma once
// Exact bounds of a piece of a triangle cut by an axis-aligned plane, the split primitive of every split builder
// (SBVH's reference splitting, Stich et al. 2009 sec. 4.3; split clipping, Ganestam and Doggett 2016 sec. 3.2;
// early split clipping, Ernst and Greiner 2007 alg. 4). The bounds are those of the clipped polygon, not of a
// cut box, and they are rounded outwards so that they always contain the exact piece.
#include "base/geometry.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace canopy {

// std::nextafter(x, up ? +inf : -inf) without the library call, a sizeable share of an SBVH build's clipping
// (docs/results.md#builds-and-layouts).
inline float next_float(float x, bool up) {
    if (!std::isfinite(x)) return std::nextafter(x, up ? INFINITY : -INFINITY);
    if (x == 0.0f) return up ? std::numeric_limits<float>::denorm_min() : -std::numeric_limits<float>::denorm_min();
    const uint32_t bits = std::bit_cast<uint32_t>(x);
    return std::bit_cast<float>((x > 0.0f) == up ? bits + 1 : bits - 1);  // the magnitude grows or shrinks by an ulp
}

// The point where edge a-b crosses the plane (axis, position), computed in double and widened to a float box
// that contains it: the other two coordinates round either way by at most an ulp.
inline BBox edge_plane_crossing(const Vec3& a, const Vec3& b, int axis, float position) {
    const double s = (double(position) - double(a[axis])) / (double(b[axis]) - double(a[axis]));
    BBox crossing;
    for (int k = 0; k < 3; ++k) {
        if (k == axis) {
            crossing.lower[k] = crossing.upper[k] = position;
            continue;
        }
        const double exact = double(a[k]) + s * (double(b[k]) - double(a[k]));
        const float rounded = float(exact);
        crossing.lower[k] = double(rounded) <= exact ? rounded : next_float(rounded, false);
        crossing.upper[k] = double(rounded) >= exact ? rounded : next_float(rounded, true);
    }
    return crossing;
}

// The boxes of the parts of `triangle` on each side of the plane, each intersected with `piece` (the bounds of
// the reference being split, which may already be a clipped part of the triangle). A side the triangle does not
// reach comes back empty. The left box ends at the plane and the right one starts there.
inline std::pair<BBox, BBox> split_triangle_bounds(const Triangle& triangle, const BBox& piece, int axis, float position) {
    const Vec3 v[3] = {triangle.v0, triangle.v1, triangle.v2};
    BBox left, right;
    for (int i = 0; i < 3; ++i) {
        const Vec3& a = v[i];
        const Vec3& b = v[(i + 1) % 3];
        if (a[axis] <= position) left.extend(a);
        if (a[axis] >= position) right.extend(a);
        if ((a[axis] < position && b[axis] > position) || (a[axis] > position && b[axis] < position)) {
            const BBox crossing = edge_plane_crossing(a, b, axis, position);
            left.extend(crossing);
            right.extend(crossing);
        }
    }
    auto clip = [&](BBox box) {
        box.lower = glm::max(box.lower, piece.lower);
        box.upper = glm::min(box.upper, piece.upper);
        return box.empty() ? BBox{} : box;
    };
    left.upper[axis] = std::min(left.upper[axis], position);
    right.lower[axis] = std::max(right.lower[axis], position);
    return {clip(left), clip(right)};
}

}  // namespace canopy
