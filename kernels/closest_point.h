#pragma once
// The point of a flat tree's triangles nearest to a query point: a best-first walk of WideBvh<N> (any width) that
// visits children nearest box first and skips every box farther than the nearest triangle found, the triangle's
// nearest point computed in double precision by Ericson's region test (Real-Time Collision Detection, sec. 5.1.5).
#include "accel/wide_bvh.h"
#include "kernels/all_hits.h"

#include <glm/vec3.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <limits>

namespace canopy {

using DVec3 = glm::dvec3;

struct PointHit {
    double distance2 = std::numeric_limits<double>::infinity();  // squared distance to `point`
    DVec3 point{0.0};
    double u = 0, v = 0;  // barycentric weights of the triangle's second and third vertex
    uint32_t prim = Hit::kNone;

    bool found() const { return prim != Hit::kNone; }
};

// The nearest point of segment [a, b] to p, as the weight of b.
inline double segment_weight(const DVec3& p, const DVec3& a, const DVec3& b) {
    const DVec3 ab = b - a;
    const double length2 = glm::dot(ab, ab);
    return length2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
}

// The nearest point of triangle (a, b, c) to p as barycentric weights (u, v) of b and c: Ericson's Voronoi-region
// test, sec. 5.1.5. A degenerate triangle (a segment or a point) takes the nearest of its edges.
inline std::pair<double, double> closest_weights(const DVec3& p, const DVec3& a, const DVec3& b, const DVec3& c) {
    const DVec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return {0.0, 0.0};  // vertex region a
    const DVec3 bp = p - b;
    const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return {1.0, 0.0};  // vertex region b
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return {d1 / (d1 - d3), 0.0};  // edge ab
    const DVec3 cp = p - c;
    const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return {0.0, 1.0};  // vertex region c
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return {0.0, d2 / (d2 - d6)};  // edge ac
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {  // edge bc
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return {1.0 - w, w};
    }
    const double sum = va + vb + vc;  // |ab x ac|^2 (Lagrange's identity)
    if (sum > 0.0) return {vb / sum, vc / sum};  // the face
    // No face region: the triangle is a segment or a point, whose nearest point lies on one of its edges.
    const auto distance2 = [&](std::pair<double, double> uv) {
        const DVec3 d = a + uv.first * ab + uv.second * ac - p;
        return glm::dot(d, d);
    };
    const double w_ac = segment_weight(p, a, c), w_bc = segment_weight(p, b, c);
    std::pair<double, double> best{segment_weight(p, a, b), 0.0};
    for (const std::pair<double, double> uv : {std::pair{0.0, w_ac}, std::pair{1.0 - w_bc, w_bc}})
        if (distance2(uv) < distance2(best)) best = uv;
    return best;
}

// Squared distance from p to a box (0 inside it).
inline double box_distance2(const DVec3& p, const BBox& box) {
    double sum = 0.0;
    for (int a = 0; a < 3; ++a) {
        const double d = std::max({double(box.lower[a]) - p[a], 0.0, p[a] - double(box.upper[a])});
        sum += d * d;
    }
    return sum;
}

// The nearest point to p of the tree's triangles no farther than sqrt(max_distance2), or no hit.
template <int N>
PointHit closest_point(const WideBvh<N>& bvh, const DVec3& p, double max_distance2 = std::numeric_limits<double>::infinity()) {
    PointHit best;
    best.distance2 = max_distance2;
    if (bvh.nodes.empty()) return best;
    struct Entry {
        uint32_t child, count;
        double distance2;
    };
    Entry stack[kMaxBvhDepth * (N - 1) + 1];
    Entry* sp = stack;
    *sp++ = {0, 0, 0.0};
    while (sp != stack) {
        const Entry entry = *--sp;
        if (entry.distance2 > best.distance2) continue;
        if (entry.count == 0) {
            const WideNode<N>& node = bvh.nodes[entry.child];
            // Children within reach pushed farthest first by insertion, so the nearest is taken next and shrinks
            // the search soonest.
            Entry* const base = sp;
            for (int i = 0; i < N; ++i) {
                if (node.is_empty(i)) continue;
                const double d2 = box_distance2(p, bvh.frame.box(node, i));  // contains the child's exact box
                if (d2 > best.distance2) continue;
                Entry* j = sp++;
                for (; j > base && j[-1].distance2 < d2; --j) *j = j[-1];
                *j = {node.child[i], node.count[i], d2};
            }
            continue;
        }
        const uint32_t end = entry.child + (N == 2 ? entry.count : leaf_entries(N, entry.count));
        for (uint32_t e = entry.child; e < end; ++e)
            for_each_leaf_triangle(bvh.leaves[e], [&](const Triangle& t, uint32_t prim) {
                const DVec3 a(t.v0), b(t.v1), c(t.v2);
                const auto [u, v] = closest_weights(p, a, b, c);
                const DVec3 q = a + u * (b - a) + v * (c - a);
                const double d2 = glm::dot(q - p, q - p);
                if (d2 < best.distance2 || (d2 == best.distance2 && prim < best.prim)) best = {d2, q, u, v, prim};
            });
    }
    return best;
}

}  // namespace canopy
