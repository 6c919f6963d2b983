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

// A node of either kind of tree as the EPO walk sees it: its box, its cost C_n, and the range of reference
// positions its subtree holds (every builder and the collapse lay a subtree's leaves out contiguously).
struct NodeView {
    BBox bounds;
    double cost;
    RefRange refs;
    bool leaf;
    uint32_t id;  // binary: node index; wide: inner node index, or for a leaf its first entry
};

// Binary trees: references are Bvh::refs positions.
class BinaryView {
public:
    BinaryView(const Bvh& bvh, SahCosts costs) : bvh_(bvh), costs_(costs), ranges_(bvh.nodes.size()) { fill(0); }

    NodeView root() const { return view(0); }
    void children(const NodeView& n, std::vector<NodeView>& out) const {
        const uint32_t first = bvh_.nodes[n.id].index;
        out.push_back(view(first));
        out.push_back(view(first + 1));
    }
    // Which triangle each reference position holds.
    uint32_t reference_count() const { return uint32_t(bvh_.refs.size()); }
    uint32_t prim_at(uint32_t position) const { return bvh_.refs[position]; }

private:
    NodeView view(uint32_t i) const {
        const BvhNode& n = bvh_.nodes[i];
        return {n.bounds, n.is_leaf() ? costs_.triangle * double(n.count) : double(costs_.inner), ranges_[i], n.is_leaf(), i};
    }
    RefRange fill(uint32_t i) {
        const BvhNode& n = bvh_.nodes[i];
        if (n.is_leaf()) return ranges_[i] = {n.index, n.index + n.count};
        const RefRange l = fill(n.index), r = fill(n.index + 1);
        return ranges_[i] = {std::min(l.first, r.first), std::max(l.second, r.second)};
    }
    const Bvh& bvh_;
    SahCosts costs_;
    std::vector<RefRange> ranges_;
};

// Wide trees: a leaf is a child slot of its parent; references are triangle slots in WideBvh::leaves (one per
// LeafTriangle, block_lanes(N) per TriangleBlock, padding lanes holding no triangle). A leaf's references are its
// own triangles' slots, also where one-triangle leaves share a block (a lane each, in child order: wide_bvh.h).
template <int N>
class WideView {
public:
    WideView(const WideBvh<N>& bvh, SahCosts costs) : bvh_(bvh), costs_(costs), ranges_(bvh.nodes.size()) { fill(0); }

    NodeView root() const {
        BBox box;
        for (int i = 0; i < N; ++i) box.extend(child_box(0, i));
        return {box, costs_.inner, ranges_[0], false, 0};
    }
    void children(const NodeView& n, std::vector<NodeView>& out) const {
        const WideNode<N>& node = bvh_.nodes[n.id];
        const std::array<RefRange, N> leaves = leaf_ranges(node);
        for (int i = 0; i < N; ++i) {
            if (node.is_empty(i)) continue;
            if (node.is_leaf(i))
                out.push_back({child_box(n.id, i), costs_.triangle * double(node.count[i]), leaves[i], true, node.child[i]});
            else
                out.push_back({child_box(n.id, i), costs_.inner, ranges_[node.child[i]], false, node.child[i]});
        }
    }
    uint32_t reference_count() const { return uint32_t(bvh_.leaves.size()) * kPerEntry; }
    uint32_t prim_at(uint32_t position) const {
        if constexpr (N > 2) return bvh_.leaves[position / kPerEntry].prim[position % kPerEntry];
        else return bvh_.leaves[position].prim;
    }

private:
    static constexpr uint32_t kPerEntry = uint32_t(block_lanes(N));
    // Each leaf child's slots: its blocks' lanes from the first, or for a one-triangle leaf in blocks its lane in
    // the block it shares, one per such sibling before it.
    static std::array<RefRange, N> leaf_ranges(const WideNode<N>& node) {
        std::array<RefRange, N> ranges{};
        uint32_t shared_block = WideNode<N>::kEmpty, lane = 0;
        for (int i = 0; i < N; ++i) {
            if (!node.is_leaf(i)) continue;
            uint32_t first = node.child[i] * kPerEntry;
            if (N > 2 && node.count[i] == 1) {
                lane = node.child[i] == shared_block ? lane + 1 : 0;
                shared_block = node.child[i];
                first += lane;
            }
            ranges[i] = {first, first + node.count[i]};
        }
        return ranges;
    }
    BBox child_box(uint32_t node, int i) const {
        return bvh_.frame.box(bvh_.nodes[node], i);
    }
    RefRange fill(uint32_t index) {
        RefRange range{~0u, 0};
        const WideNode<N>& node = bvh_.nodes[index];
        const std::array<RefRange, N> leaves = leaf_ranges(node);
        for (int i = 0; i < N; ++i) {
            if (node.is_empty(i)) continue;
            const RefRange c = node.is_leaf(i) ? leaves[i] : fill(node.child[i]);
            range = {std::min(range.first, c.first), std::max(range.second, c.second)};
        }
        return ranges_[index] = range;
    }
    const WideBvh<N>& bvh_;
    SahCosts costs_;
    std::vector<RefRange> ranges_;
};

template <class View>
double epo_of(const View& view, std::span<const Triangle> triangles) {
    // Each triangle's reference positions, as offsets into one array (several when references were split).
    const uint32_t references = view.reference_count();
    std::vector<uint32_t> first(triangles.size() + 1, 0), positions;
    for (uint32_t p = 0; p < references; ++p)
        if (view.prim_at(p) < triangles.size()) ++first[view.prim_at(p) + 1];
    for (size_t i = 0; i < triangles.size(); ++i) first[i + 1] += first[i];
    positions.resize(first.back());
    {
        std::vector<uint32_t> fill(first.begin(), first.end() - 1);
        for (uint32_t p = 0; p < references; ++p)
            if (view.prim_at(p) < triangles.size()) positions[fill[view.prim_at(p)]++] = p;
    }
    auto in_subtree = [&](uint32_t prim, const RefRange& range) {
        for (uint32_t i = first[prim]; i < first[prim + 1]; ++i)
            if (positions[i] >= range.first && positions[i] < range.second) return true;
        return false;
    };
    auto overlap_of = [&](uint32_t prim) {
        const Triangle& t = triangles[prim];
        const BBox box = BBox::of(t);
        double sum = 0.0;
        std::vector<NodeView> stack{view.root()};
        while (!stack.empty()) {
            const NodeView n = stack.back();
            stack.pop_back();
            if (glm::any(glm::greaterThan(box.lower, n.bounds.upper)) || glm::any(glm::lessThan(box.upper, n.bounds.lower)))
                continue;
            const double area = clipped_area(t, n.bounds);
            if (area <= 0.0) continue;
            if (!in_subtree(prim, n.refs)) sum += n.cost * area;
            if (!n.leaf) view.children(n, stack);
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
    return bvh.nodes.empty() ? 0.0 : epo_of(BinaryView(bvh, costs), triangles);
}

template <int N>
double epo_cost(const WideBvh<N>& bvh, std::span<const Triangle> triangles, SahCosts costs) {
    return bvh.nodes.empty() ? 0.0 : epo_of(WideView<N>(bvh, costs), triangles);
}

template <int N>
double sah_cost(const WideBvh<N>& bvh, SahCosts costs) {
    if (bvh.nodes.empty()) return 0.0;
    const WideView<N> view(bvh, costs);
    const double root_area = view.root().bounds.half_area();
    double sum = 0.0;
    std::vector<NodeView> stack{view.root()};
    while (!stack.empty()) {
        const NodeView n = stack.back();
        stack.pop_back();
        sum += n.cost * n.bounds.half_area();
        if (!n.leaf) view.children(n, stack);
    }
    return root_area > 0.0 ? sum / root_area : 0.0;
}

double sibling_overlap(const Bvh& bvh) {
    double overlap = 0.0, inner = 0.0;
    for (const BvhNode& node : bvh.nodes) {
        if (node.is_leaf()) continue;
        const BBox& left = bvh.nodes[node.index].bounds;
        const BBox& right = bvh.nodes[node.index + 1].bounds;
        const BBox shared{glm::max(left.lower, right.lower), glm::min(left.upper, right.upper)};  // empty() if apart
        overlap += shared.half_area();
        inner += node.bounds.half_area();
    }
    return inner > 0.0 ? overlap / inner : 0.0;
}

template double epo_cost<2>(const WideBvh<2>&, std::span<const Triangle>, SahCosts);
template double epo_cost<4>(const WideBvh<4>&, std::span<const Triangle>, SahCosts);
template double epo_cost<8>(const WideBvh<8>&, std::span<const Triangle>, SahCosts);
template double sah_cost<2>(const WideBvh<2>&, SahCosts);
template double sah_cost<4>(const WideBvh<4>&, SahCosts);
template double sah_cost<8>(const WideBvh<8>&, SahCosts);

}  // namespace canopy
