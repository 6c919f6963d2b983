#include "accel/metrics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <array>

namespace canopy {
namespace {

using DVec3 = glm::dvec3;

// Sutherland–Hodgman: keeps the part of a convex polygon on the inside of the plane x[axis] (>= or <=) bound.
int clip_polygon(const DVec3* in, int n, DVec3* out, int axis, double bound, bool keep_above) {
    int m = 0;
    for (int i = 0; i < n; ++i) {
        const DVec3& a = in[i];
        const DVec3& b = in[(i + 1) % n];
        const double da = keep_above ? a[axis] - bound : bound - a[axis];
        const double db = keep_above ? b[axis] - bound : bound - b[axis];
        if (da >= 0) out[m++] = a;
        if ((da >= 0) != (db >= 0)) out[m++] = a + (b - a) * (da / (da - db));
    }
    return m;
}

using RefRange = std::pair<uint32_t, uint32_t>;

// The range of ref positions the subtree of `node` holds (every builder lays a subtree's leaves out as one
// contiguous run of refs), for this node and all below it.
RefRange fill_ref_ranges(const Bvh& bvh, uint32_t node, std::vector<RefRange>& ranges) {
    const BvhNode& n = bvh.nodes[node];
    if (n.is_leaf()) return ranges[node] = {n.index, n.index + n.count};
    const RefRange left = fill_ref_ranges(bvh, n.index, ranges), right = fill_ref_ranges(bvh, n.index + 1, ranges);
    return ranges[node] = {std::min(left.first, right.first), std::max(left.second, right.second)};
}

}  // namespace

double clipped_area(const Triangle& t, const BBox& b) {
    std::array<DVec3, 9> buffers[2];
    buffers[0][0] = t.v0, buffers[0][1] = t.v1, buffers[0][2] = t.v2;
    int n = 3, current = 0;
    for (int axis = 0; axis < 3 && n > 0; ++axis) {
        n = clip_polygon(buffers[current].data(), n, buffers[1 - current].data(), axis, b.lower[axis], true);
        current = 1 - current;
        n = clip_polygon(buffers[current].data(), n, buffers[1 - current].data(), axis, b.upper[axis], false);
        current = 1 - current;
    }
    DVec3 twice_area(0.0);
    for (int i = 1; i + 1 < n; ++i)
        twice_area += glm::cross(buffers[current][i] - buffers[current][0], buffers[current][i + 1] - buffers[current][0]);
    return 0.5 * glm::length(twice_area);
}

double epo_cost(const Bvh& bvh, std::span<const Triangle> triangles, SahCosts costs) {
    if (bvh.nodes.empty()) return 0.0;
    std::vector<RefRange> ranges(bvh.nodes.size());
    fill_ref_ranges(bvh, 0, ranges);
    // Each triangle's ref positions, as offsets into one array (several when references were split).
    std::vector<uint32_t> first(triangles.size() + 1, 0), positions(bvh.refs.size());
    for (uint32_t prim : bvh.refs) ++first[prim + 1];
    for (size_t i = 0; i < triangles.size(); ++i) first[i + 1] += first[i];
    {
        std::vector<uint32_t> fill(first.begin(), first.end() - 1);
        for (uint32_t p = 0; p < bvh.refs.size(); ++p) positions[fill[bvh.refs[p]]++] = p;
    }
    auto in_subtree = [&](uint32_t prim, uint32_t node) {
        for (uint32_t i = first[prim]; i < first[prim + 1]; ++i)
            if (positions[i] >= ranges[node].first && positions[i] < ranges[node].second) return true;
        return false;
    };
    auto node_cost = [&](const BvhNode& n) { return n.is_leaf() ? costs.triangle * double(n.count) : double(costs.inner); };
    auto overlap_of = [&](uint32_t prim) {
        const Triangle& t = triangles[prim];
        const BBox box = BBox::of(t);
        double sum = 0.0;
        std::vector<uint32_t> stack{0};
        while (!stack.empty()) {
            const uint32_t index = stack.back();
            stack.pop_back();
            const BvhNode& n = bvh.nodes[index];
            if (glm::any(glm::greaterThan(box.lower, n.bounds.upper)) || glm::any(glm::lessThan(box.upper, n.bounds.lower)))
                continue;
            const double area = clipped_area(t, n.bounds);
            if (area <= 0.0) continue;
            if (!in_subtree(prim, index)) sum += node_cost(n) * area;
            if (!n.is_leaf()) stack.insert(stack.end(), {n.index, n.index + 1});
        }
        return sum;
    };
    using Sums = std::pair<double, double>;  // overlap cost, surface area
    const Sums total = tbb::parallel_deterministic_reduce(
        tbb::blocked_range<uint32_t>(0, uint32_t(triangles.size()), 1024), Sums{0.0, 0.0},
        [&](const tbb::blocked_range<uint32_t>& r, Sums acc) {
            for (uint32_t prim = r.begin(); prim != r.end(); ++prim) {
                acc.first += overlap_of(prim);
                acc.second += double(triangle_area(triangles[prim]));
            }
            return acc;
        },
        [](Sums a, const Sums& b) { return Sums{a.first + b.first, a.second + b.second}; });
    return total.second > 0.0 ? total.first / total.second : 0.0;
}

}  // namespace canopy
