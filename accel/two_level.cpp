#include "accel/two_level.h"

#include "accel/parallel.h"
#include "accel/top_down_builder.h"

#include <glm/gtc/matrix_inverse.hpp>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>

namespace canopy {

namespace {

// The float below a finite x, by its bits and without branches (std::nextafter is a library call, and the
// rounding of a thousand box transforms a build goes either way at random): +0 counts as -0, whose successor
// downwards is -denorm_min; a positive float's bits step down, a negative's up.
float next_down(float x) {
    const int32_t bits = std::bit_cast<int32_t>(x == 0.0f ? -0.0f : x);
    return std::bit_cast<float>(bits - (1 + 2 * (bits >> 31)));
}

float round_down(double x) {
    const float f = float(x);
    return double(f) > x ? next_down(f) : f;
}

float round_up(double x) {
    const float f = float(x);
    return double(f) < x ? -next_down(-f) : f;
}

}  // namespace

// Arvo 1990 ("Transforming Axis-Aligned Bounding Boxes"): per world axis, the translation plus, for each object
// axis, the smaller (larger) of the matrix entry times the box's lower and upper bound; the extremes of the eight
// transformed corners, in double, rounded outwards.
BBox transform_bounds(const glm::mat4& m, const BBox& box) {
    BBox out;
    if (box.empty()) return out;
    for (int a = 0; a < 3; ++a) {
        double low = 0.0, high = 0.0;
        for (int j = 0; j < 3; ++j) {
            const double p = double(m[j][a]) * double(box.lower[j]), q = double(m[j][a]) * double(box.upper[j]);
            low += std::min(p, q), high += std::max(p, q);
        }
        low += double(m[3][a]), high += double(m[3][a]);
        out.lower[a] = round_down(low);
        out.upper[a] = round_up(high);
    }
    return out;
}

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) { return std::chrono::duration<double, std::milli>(Clock::now() - start).count(); }

// An identity placement of an object whose planes are in a frame of its own (not at the world origin, see
// build_two_level) is entered as a transformed one, so that its ray is translated into that frame.
PlacedObject place(const TwoLevelInstance& instance, const ObjectTree& object) {
    const bool identity = instance.to_world == glm::mat4(1.0f) && object.frame.origin == Vec3(0.0f);
    PlacedObject placed{instance.object, instance.prim_offset - object.prim_base, identity};
    const glm::dmat4 inverse = glm::inverse(glm::dmat4(instance.to_world));
    for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 4; ++col) placed.world_to_object[row][col] = float(inverse[col][row]);
    return placed;
}

// A BVH node build reference (sec. 3.2): a node of an instance's object tree, its world bounds, and the
// estimated number of triangles below it (the parent's divided by its child count, sec. 5.3).
struct BRef {
    static constexpr uint32_t kWholeLeaf = 0xffffffffu;
    BBox bounds;
    uint32_t instance;
    uint32_t child, count;  // as WideNode names a child: count 0 is an inner node, count > 0 a leaf of that many
    float prims;
    uint32_t triangle = kWholeLeaf;  // of an opened leaf: the one triangle (of leaf child, count) referred to
    float children_area = 0.0f;      // of a transformed inner node: its children's world boxes' areas summed
    bool kept = false;               // refused opening (fewer_entries): stays closed in every segment below

    bool one_triangle() const { return triangle != kWholeLeaf; }
    // Inner nodes, and leaves of several triangles (the paper opens inner nodes only; sec. 7 leaves leaves to
    // future work).
    bool openable() const { return !kept && !one_triangle() && count != 1; }
};

// BBox::extend written out, which the top level's hot loops then inline.
[[gnu::always_inline]] inline void grow(BBox& box, const BBox& b) {
    for (int a = 0; a < 3; ++a) {
        box.lower[a] = std::min(box.lower[a], b.lower[a]);
        box.upper[a] = std::max(box.upper[a], b.upper[a]);
    }
}

struct PlacedTriangle {
    Triangle triangle;
    uint32_t prim;
};

// Triangle i of the leaf starting at pool leaf entry `first`, with the id its leaf holds.
inline PlacedTriangle leaf_triangle(const LeafTriangle* leaves, uint32_t first, uint32_t i) {
    const LeafTriangle& t = leaves[first + i];
    return {{t.v0, t.v1, t.v2}, t.prim};
}

template <int W>
PlacedTriangle leaf_triangle(const TriangleBlock<W>* blocks, uint32_t first, uint32_t i) {
    const TriangleBlock<W>& block = blocks[first + i / W];
    const uint32_t lane = i % W;
    Vec3 v[3];
    for (int vertex = 0; vertex < 3; ++vertex)
        for (int a = 0; a < 3; ++a) v[vertex][a] = block.v[vertex][a][lane];
    return {{v[0], v[1], v[2]}, block.prim[lane]};
}

// The triangle of a one-triangle BRef in world space, with its scene-wide id: what the top level's own leaf holds.
// Vertices are transformed as flatten() places a scene's triangles, so a hit on them is the flat BVH's hit.
template <int N>
PlacedTriangle world_triangle(const TwoLevelBvh<N>& bvh, const BRef& r) {
    PlacedTriangle t = leaf_triangle(bvh.pool.leaves.data(), r.child, r.triangle);
    const PlacedObject& placed = bvh.instances[r.instance];
    t.prim += placed.prim_offset;
    if (!placed.identity) {
        const glm::mat4& m = bvh.to_world[r.instance];
        for (Vec3* v : {&t.triangle.v0, &t.triangle.v1, &t.triangle.v2}) *v = Vec3(m * glm::vec4(*v, 1.0f));
    }
    return t;
}

// Appends a leaf of the given triangles to `leaves`: LeafTriangles, or blocks whose lanes past the last triangle
// hold a degenerate triangle at the origin (never hit), as collapse fills an object's leaves.
inline void append_leaf(std::vector<LeafTriangle, HugePageAllocator<LeafTriangle>>& leaves,
                        std::span<const PlacedTriangle> triangles) {
    for (const PlacedTriangle& t : triangles) leaves.push_back({t.triangle.v0, t.prim, t.triangle.v1, t.triangle.v2});
}

template <int W>
void append_leaf(std::vector<TriangleBlock<W>, HugePageAllocator<TriangleBlock<W>>>& blocks,
                 std::span<const PlacedTriangle> triangles) {
    for (size_t first = 0; first < triangles.size(); first += W) {
        TriangleBlock<W>& block = blocks.emplace_back();
        for (size_t lane = 0; lane < W; ++lane) {
            const bool used = first + lane < triangles.size();
            const Triangle t = used ? triangles[first + lane].triangle : Triangle{Vec3(0), Vec3(0), Vec3(0)};
            const Vec3* vertices[3] = {&t.v0, &t.v1, &t.v2};
            for (int v = 0; v < 3; ++v)
                for (int a = 0; a < 3; ++a) block.v[v][a][lane] = (*vertices[v])[a];
            block.prim[lane] = used ? triangles[first + lane].prim : TriangleBlock<W>::kNone;
        }
    }
}

// Sec. 5.2: objects get max(4 x #instances, #instances + #triangles / 1000) BRefs, instanced objects 4 x #instances;
// or as set. The paper's #triangles / 1000 alone would not open every object's root once in crytek-sponza, and
// an array of twice the placements left its re-braided tree visiting more nodes a ray than the flat tree
// (docs/results.md#closing-the-two-level-gap-on-crytek-sponza-re-braiding-paper-table-1).
size_t bref_capacity(const std::vector<ObjectTree>& objects, const std::vector<TwoLevelInstance>& instances,
                     const TwoLevelSettings& settings) {
    const size_t n = instances.size();
    if (settings.top == TopLevel::TwoLevel) return std::max<size_t>(n, 1);
    if (settings.brefs_per_placement) return std::max<size_t>(n * settings.brefs_per_placement, 1);
    const bool instanced = n > objects.size();
    uint64_t triangles = 0;
    for (const TwoLevelInstance& i : instances) triangles += objects[i.object].triangles;
    return std::max<size_t>(instanced ? 4 * n : std::max<size_t>(4 * n, n + triangles / 1000), 1);
}

constexpr uint32_t kMaxTopLevelBins = 64;  // the binning's arrays live on the stack
constexpr uint32_t kSweepUpTo = 16;        // segments of at most this many BRefs are split by a full sweep

struct Segment {
    uint32_t begin, end, extra_end;  // BRefs in [begin, end), free slots for opening in [end, extra_end) (sec. 5.2)
};

// The top level's search, for TopDownBuilder: a segment of BRefs is opened (re-braiding) before it is decided on,
// becomes a leaf when it holds one BRef or a few triangles that the SAH keeps together, and is otherwise always
// split, by a sweep or by binned SAH over the BRefs' centroids weighted by their triangle estimates.
template <int N>
class TopLevelSearch {
public:
    struct Node {
        Segment s;
        bool open;    // whether this segment may still open BRefs (sec. 4.4: stopping holds for its whole subtree)
        BBox bounds;  // filled in by prepare
    };
    struct Split {
        bool by_sweep;
        int axis;
        uint32_t position;  // by sweep: BRefs on the left; binned: BRefs in bins [0, position) go left
        BBox centroids;     // binned: the segment's centroid bounds, which the bins divide
        float cost;
        bool found() const { return axis >= 0; }
    };
    using Children = std::pair<Node, Node>;

    TopLevelSearch(const TwoLevelBvh<N>& bvh, const std::vector<TwoLevelInstance>& instances, const TwoLevelSettings& s)
        : bvh_(bvh), instances_(instances), settings_(s), brefs_(bref_capacity(bvh.objects, instances, s)) {}

    Bvh build() {
        for (uint32_t i = 0; i < instances_.size(); ++i) {
            const ObjectTree& object = bvh_.objects[instances_[i].object];
            brefs_[i] = placed_ref(i, object.root, 0, object.bounds, float(object.triangles));
        }
        const Node all{{0, uint32_t(instances_.size()), uint32_t(brefs_.size())}, settings_.top == TopLevel::Rebraid, BBox{}};
        // Leaves of several BRefs only where leaf_without_search says so: max_leaf 1 turns the SAH's leaf test off.
        const TopDownLimits limits{1, kMedianFallbackDepth, 64};
        TopDownBuilder<TopLevelSearch> builder(*this, settings_.blas, limits, brefs_.size());
        Bvh top;
        top.nodes = builder.build(all);
        return top;
    }

    const std::vector<BRef>& brefs() const { return brefs_; }

    void prepare(Node& node) {
        if (node.open) node.open = worth_opening(node.s);
        if (node.open) node.s.end = open_wide_brefs(node.s);
        node.bounds = bounds_of(node.s);
    }
    static uint32_t count(const Node& node) { return node.s.end - node.s.begin; }
    static uint32_t first(const Node& node) { return node.s.begin; }
    static uint32_t slots(const Node& node) { return node.s.extra_end - node.s.begin; }
    static BBox box(const Node& node) { return node.bounds; }
    static float half_area(const Node& node) { return node.bounds.half_area(); }
    bool leaf_without_search(const Node& node) const { return triangle_leaf(node.s, node.bounds); }

    // Sec. 4.3: binned SAH over BRef centroids, each bin weighted by its BRefs' estimated triangle counts; a
    // handful of BRefs are swept instead.
    Split find(const Node& node) const {
        if (count(node) > kSweepUpTo) return binned_split(node.s);
        const Sweep best = sweep(node.s, [](uint32_t, float prims) { return prims; });
        return {true, best.axis, best.split, BBox{}, best.cost};
    }

    std::optional<Children> split(const Node& node, const Split& chosen) {
        const Segment& s = node.s;
        if (chosen.by_sweep) {
            std::sort(brefs_.begin() + s.begin, brefs_.begin() + s.end,
                      [&](const BRef& a, const BRef& b) { return ordered(a, b, chosen.axis); });
            return share_free_space(node, s.begin + chosen.position);
        }
        const Binning bin(chosen.centroids, chosen.axis, int(settings_.bins));
        BRef* mid = std::partition(brefs_.data() + s.begin, brefs_.data() + s.end,
                                   [&](const BRef& r) { return bin(r) < int(chosen.position); });
        return share_free_space(node, uint32_t(mid - brefs_.data()));
    }

    // All centroids in one point (or too deep): split in the middle of the largest axis's order.
    Children median(const Node& node) {
        const Segment& s = node.s;
        const int axis = centroid_bounds(s).largest_axis();
        const uint32_t mid = s.begin + (s.end - s.begin) / 2;
        std::nth_element(brefs_.begin() + s.begin, brefs_.begin() + mid, brefs_.begin() + s.end,
                         [&](const BRef& a, const BRef& b) { return ordered(a, b, axis); });
        return share_free_space(node, mid);
    }

private:
    // A BRef of node (child, count) of an instance's object tree, whose object box is `box`. Sec. 5.4: a
    // transformed node's world box is conservative, its object box transformed. Re-braiding looks into the object
    // tree anyway, so for an inner node it takes the union of its children's transformed boxes, which is tighter:
    // fewer rays enter an instance only to miss it (docs/results.md#builds-and-layouts). The same boxes' areas
    // decide whether opening it is worth the entries (fewer_entries).
    BRef placed_ref(uint32_t instance, uint32_t child, uint32_t count, const BBox& box, float prims) const {
        BRef r{placed_box(instance, box), instance, child, count, prims};
        if (bvh_.instances[instance].identity || count || settings_.top == TopLevel::TwoLevel) return r;
        const WideNode<N>& node = bvh_.pool.nodes[child];
        r.bounds = BBox{};
        for (int c = 0; c < N; ++c) {
            if (node.is_empty(c)) continue;
            const BBox world = placed_box(instance, object_frame(instance).box(node, c));
            grow(r.bounds, world);
            r.children_area += world.half_area();
        }
        return r;
    }

    const PlaneFrame& object_frame(uint32_t instance) const { return bvh_.objects[instances_[instance].object].frame; }

    // An object-space box in world space, conservatively.
    BBox placed_box(uint32_t instance, const BBox& box) const {
        return bvh_.instances[instance].identity ? box : transform_bounds(instances_[instance].to_world, box);
    }

    // Sec. 4.4: no opening once a segment holds one instance only, or at most 4 BRefs that barely overlap (no
    // pair whose common box has a tenth of the smaller one's area). Stopping holds for the whole subtree.
    bool worth_opening(const Segment& s) const {
        bool single = true;
        for (uint32_t i = s.begin + 1; i < s.end; ++i) single &= brefs_[i].instance == brefs_[s.begin].instance;
        if (single) return false;
        if (s.end - s.begin > 4) return true;
        for (uint32_t i = s.begin; i < s.end; ++i)
            for (uint32_t j = i + 1; j < s.end; ++j) {
                const BBox& a = brefs_[i].bounds;
                const BBox& b = brefs_[j].bounds;
                const BBox common{glm::max(a.lower, b.lower), glm::min(a.upper, b.upper)};
                if (!common.empty() && common.half_area() > 0.1f * std::min(a.half_area(), b.half_area())) return true;
            }
        return false;
    }

    // Sec. 4.2 and 5.3: every openable BRef wider than open_extent of the segment's largest extent is replaced by
    // its children: the first in its slot, the others appended while the segment's free space lasts. The widest
    // go first (sec. 7 suggests prioritising by size): with the space of sec. 5.2, array order left crytek-sponza
    // slower than its flat tree and widest first did not (docs/results.md#builds-and-layouts).
    uint32_t open_wide_brefs(const Segment& s) {
        if (s.extra_end == s.end) return s.end;  // no space (only a node of one child would fit: not worth a sort)
        const BBox bounds = bounds_of(s);
        const int dim = bounds.largest_axis();
        const float threshold = settings_.open_extent * bounds.extent()[dim];
        BRef* first = brefs_.data() + s.begin;
        BRef* wide_end = std::partition(first, brefs_.data() + s.end, [&](const BRef& r) {
            return r.openable() && r.bounds.extent()[dim] > threshold;
        });
        std::sort(first, wide_end, [&](const BRef& a, const BRef& b) {
            const float ea = a.bounds.extent()[dim], eb = b.bounds.extent()[dim];
            return ea != eb ? ea > eb : ordered(a, b, dim);
        });
        uint32_t end = s.end;
        for (uint32_t i = s.begin; i < uint32_t(wide_end - brefs_.data()); ++i) {
            const bool opened = brefs_[i].count ? open_leaf(i, end, s.extra_end) : open_node(i, end, s.extra_end);
            if (!opened) break;  // out of space: the rest stay closed
        }
        return end;
    }

    // Replaces inner BRef i by its children, the first in its slot, the others at `end`; false when they do not
    // fit before `limit`.
    bool open_node(uint32_t i, uint32_t& end, uint32_t limit) {
        BRef& parent = brefs_[i];
        const WideNode<N>& node = bvh_.pool.nodes[parent.child];
        uint32_t children = 0;
        for (int c = 0; c < N; ++c) children += !node.is_empty(c);
        if (end + children - 1 > limit) return false;
        if (!fewer_entries(parent)) {
            parent.kept = true;
            return true;
        }
        const float prims = parent.prims / float(children);
        const uint32_t instance = parent.instance;
        bool first = true;
        for (int c = 0; c < N; ++c) {
            if (node.is_empty(c)) continue;
            // The first child takes the parent's slot.
            brefs_[first ? i : end++] = placed_ref(instance, node.child[c], node.count[c], object_frame(instance).box(node, c),
                                                   estimated_prims(node, c, prims));
            first = false;
        }
        return true;
    }

    // Opening a leaf (our extension, after sec. 7): a BRef per triangle, boxed in world space. The top level then
    // sorts an object's triangles among other objects' as a single BVH would: on crytek-sponza, objects of a few
    // huge triangles (the outer walls, spanning the whole scene) otherwise make leaves whose boxes every ray enters.
    // The triangles reach the top level's own leaves in world space (pool_top_level), needing no entry.
    bool open_leaf(uint32_t i, uint32_t& end, uint32_t limit) {
        const BRef parent = brefs_[i];
        if (end + parent.count - 1 > limit) return false;
        for (uint32_t t = 0; t < parent.count; ++t) {
            BRef one{BBox{}, parent.instance, parent.child, parent.count, 1.0f, t};
            one.bounds = BBox::of(world_triangle(bvh_, one).triangle);
            brefs_[t == 0 ? i : end++] = one;
        }
        return true;
    }

    // Opening a BRef that traversal reaches through an instance entry (a transformed placement) trades one entry,
    // with its ray transform, for one per child box the ray hits. Such a BRef is opened only when its children's
    // transformed boxes have less area together than its own box, so the expected number of entries does not grow
    // (our addition: the paper finds transforms cheap, sec. 5.5, but on zoo-64 such openings added entries and
    // time). An identity placement's BRefs need no ray transform, and open as the paper opens them.
    bool fewer_entries(const BRef& parent) const {
        return bvh_.instances[parent.instance].direct() || parent.children_area < parent.bounds.half_area();
    }

    // Sec. 5.3 estimates a child's triangles as the parent's divided by its children; a leaf child's count is
    // in the node already, so it is exact.
    static float estimated_prims(const WideNode<N>& node, int c, float estimate) {
        return node.is_leaf(c) ? float(node.count[c]) : estimate;
    }

    BBox bounds_of(const Segment& s) const {
        BBox b;
        for (uint32_t i = s.begin; i < s.end; ++i) grow(b, brefs_[i].bounds);
        return b;
    }

    BBox centroid_bounds(const Segment& s) const {
        BBox centroids;
        for (uint32_t i = s.begin; i < s.end; ++i) centroids.extend(brefs_[i].bounds.center());
        return centroids;
    }

    // The binned SAH's best plane on any axis, the bins weighted by their BRefs' triangle estimates.
    Split binned_split(const Segment& s) const {
        const BBox centroids = centroid_bounds(s);
        const int bins = int(settings_.bins);
        Split best{false, -1, 0, centroids, INFINITY};
        for (int axis = 0; axis < 3; ++axis) {
            if (!(centroids.extent()[axis] > 0.0f)) continue;
            const Binning bin(centroids, axis, bins);
            std::array<BBox, kMaxTopLevelBins> box;
            std::array<float, kMaxTopLevelBins> weight{}, right_cost{};
            for (uint32_t i = s.begin; i < s.end; ++i) {
                const int b = bin(brefs_[i]);
                grow(box[size_t(b)], brefs_[i].bounds);
                weight[size_t(b)] += brefs_[i].prims;
            }
            BBox right;
            float right_weight = 0.0f;
            for (int b = bins - 1; b > 0; --b) {
                grow(right, box[size_t(b)]), right_weight += weight[size_t(b)];
                right_cost[size_t(b)] = right.half_area() * right_weight;
            }
            BBox left;
            float left_weight = 0.0f;
            for (int b = 1; b < bins; ++b) {
                grow(left, box[size_t(b - 1)]), left_weight += weight[size_t(b - 1)];
                const float cost = left.half_area() * left_weight + right_cost[size_t(b)];
                if (left_weight > 0.0f && right_cost[size_t(b)] > 0.0f && cost < best.cost)
                    best.cost = cost, best.axis = axis, best.position = uint32_t(b);
            }
        }
        return best;
    }

    // A BRef's bin along one axis of the segment's centroid box.
    struct Binning {
        int axis, bins;
        float lower, scale;
        Binning(const BBox& centroids, int a, int n)
            : axis(a), bins(n), lower(centroids.lower[a]), scale(float(n) * (1.0f - 1e-6f) / centroids.extent()[a]) {}
        int operator()(const BRef& r) const { return std::clamp(int((r.bounds.center()[axis] - lower) * scale), 0, bins - 1); }
    };

    // The sweep is the same SAH over every split of the centroid order on each axis: exact, and for a handful of
    // BRefs cheaper than filling the bins. Ties in the order go by instance and node, so the split is the same on
    // every run.
    struct Sweep {
        int axis = 0;
        uint32_t split = 1;  // BRefs on the left
        float cost = INFINITY;
    };

    // The split of the segment's centroid order, on any axis, of least area(left) weight(left) + area(right)
    // weight(right), a side's weight being weigh(BRefs, summed triangle estimates).
    template <class Weigh>
    Sweep sweep(const Segment& s, Weigh&& weigh) const {
        const uint32_t n = s.end - s.begin;
        std::array<uint32_t, kSweepUpTo> order;
        std::array<float, kSweepUpTo> right_cost;
        Sweep best;
        for (int axis = 0; axis < 3; ++axis) {
            std::iota(order.begin(), order.begin() + n, s.begin);
            std::sort(order.begin(), order.begin() + n,
                      [&](uint32_t a, uint32_t b) { return ordered(brefs_[a], brefs_[b], axis); });
            BBox right;
            float right_prims = 0.0f;
            for (uint32_t i = n - 1; i > 0; --i) {
                grow(right, brefs_[order[i]].bounds), right_prims += brefs_[order[i]].prims;
                right_cost[i] = right.half_area() * weigh(n - i, right_prims);
            }
            BBox left;
            float left_prims = 0.0f;
            for (uint32_t i = 1; i < n; ++i) {
                grow(left, brefs_[order[i - 1]].bounds), left_prims += brefs_[order[i - 1]].prims;
                const float cost = left.half_area() * weigh(i, left_prims) + right_cost[i];
                if (cost < best.cost) best = {axis, i, cost};
            }
        }
        return best;
    }

    // A segment of opened leaves' triangles only, few enough for one leaf, becomes one when the SAH of the object
    // builder's costs says so (against splitting it once into two leaves): the top level's leaf then mixes
    // triangles of several objects, as a flat BVH's leaves do.
    bool triangle_leaf(const Segment& s, const BBox& bounds) const {
        const uint32_t n = s.end - s.begin;
        if (n > leaf_limit_) return false;
        for (uint32_t i = s.begin; i < s.end; ++i)
            if (!brefs_[i].one_triangle()) return false;
        const BuildSettings& b = settings_.blas;
        const Sweep split = sweep(s, [&](uint32_t count, float) { return b.leaf_tests(count); });
        const float area = bounds.half_area();
        return b.costs.triangle * b.leaf_tests(n) * area <= b.costs.inner * area + b.costs.triangle * split.cost;
    }

    static bool ordered(const BRef& a, const BRef& b, int axis) {
        const float ca = a.bounds.center()[axis], cb = b.bounds.center()[axis];
        if (ca != cb) return ca < cb;
        if (a.instance != b.instance) return a.instance < b.instance;
        return a.child != b.child ? a.child < b.child : a.count != b.count ? a.count < b.count : a.triangle < b.triangle;
    }

    // Sec. 5.2: the free space goes to the children in proportion to their openable BRefs (to their sizes when
    // neither has any); the right side moves up to make room for the left's share.
    Children share_free_space(const Node& node, uint32_t mid) {
        const Segment& s = node.s;
        uint64_t open_left = 0, open_right = 0;
        for (uint32_t i = s.begin; i < mid; ++i) open_left += brefs_[i].openable();
        for (uint32_t i = mid; i < s.end; ++i) open_right += brefs_[i].openable();
        if (open_left + open_right == 0) open_left = mid - s.begin, open_right = s.end - mid;
        const uint32_t free = s.extra_end - s.end;
        const uint32_t left_free = uint32_t(uint64_t(free) * open_left / (open_left + open_right));
        if (left_free) std::move_backward(brefs_.begin() + mid, brefs_.begin() + s.end, brefs_.begin() + s.end + left_free);
        return {Node{{s.begin, mid, mid + left_free}, node.open, BBox{}},
                Node{{mid + left_free, s.end + left_free, s.extra_end}, node.open, BBox{}}};
    }

    const TwoLevelBvh<N>& bvh_;
    const std::vector<TwoLevelInstance>& instances_;
    const TwoLevelSettings& settings_;
    // A top-level leaf of triangles is one block of the SIMD kernels, or as large as an object's leaf may be.
    const uint32_t leaf_limit_ = std::min<uint32_t>(settings_.blas.max_leaf_size, N > 2 ? uint32_t(block_lanes(N)) : kSweepUpTo);
    std::vector<BRef> brefs_;
};

uint32_t one_entry_per_leaf(int, uint32_t) { return 1; }

void offset_prims(LeafTriangle& leaf, uint32_t base) { leaf.prim += base; }

template <int W>
void offset_prims(TriangleBlock<W>& block, uint32_t base) {
    for (uint32_t& prim : block.prim)
        if (prim != TriangleBlock<W>::kNone) prim += base;
}

// The offset an object's leaves bake into their triangle ids: that of its first identity placement (which the
// top level may then reach directly), else of its first placement.
std::vector<uint32_t> prim_bases(const TwoLevelInput& input) {
    std::vector<uint32_t> base(input.objects.size(), 0);
    std::vector<int> rank(input.objects.size(), 0);  // 0 none yet, 1 a placement, 2 an identity placement
    for (const TwoLevelInstance& instance : input.instances) {
        const int r = instance.to_world == glm::mat4(1.0f) ? 2 : 1;
        if (r > rank[instance.object]) rank[instance.object] = r, base[instance.object] = instance.prim_offset;
    }
    return base;
}

// Copies every object's tree into the pool, in object order: node and leaf indices offset by where the tree
// lands, triangle ids by the object's prim_base. Each tree is freed once copied. Both arrays keep room for
// `top_nodes` more, so that appending the top level and its leaves does not move the object trees.
template <int N>
void pool_object_trees(TwoLevelBvh<N>& bvh, std::vector<WideBvh<N>>& trees, size_t top_nodes) {
    std::vector<uint32_t> first_leaf(trees.size());
    uint32_t nodes = 0, leaves = 0;
    for (size_t o = 0; o < trees.size(); ++o) {
        bvh.objects[o].root = nodes, first_leaf[o] = leaves;
        nodes += uint32_t(trees[o].nodes.size()), leaves += uint32_t(trees[o].leaves.size());
    }
    bvh.object_nodes = nodes, bvh.object_leaves = leaves;
    bvh.pool.nodes.reserve(nodes + top_nodes);
    bvh.pool.nodes.resize(nodes);
    bvh.pool.leaves.reserve(leaves + top_nodes);
    bvh.pool.leaves.resize(leaves);
    parallel::for_each(trees.size(), 1, [&](size_t o) {
        const uint32_t node_base = bvh.objects[o].root, leaf_base = first_leaf[o];
        for (size_t i = 0; i < trees[o].nodes.size(); ++i) {
            WideNode<N> node = trees[o].nodes[i];
            for (int c = 0; c < N; ++c)
                if (!node.is_empty(c)) node.child[c] += node.is_leaf(c) ? leaf_base : node_base;
            bvh.pool.nodes[node_base + i] = node;
        }
        for (size_t i = 0; i < trees[o].leaves.size(); ++i) {
            bvh.pool.leaves[leaf_base + i] = trees[o].leaves[i];
            offset_prims(bvh.pool.leaves[leaf_base + i], bvh.objects[o].prim_base);
        }
        trees[o] = WideBvh<N>{};
    });
}

// Appends the collapsed top level to the pool after the object trees. A leaf of it holds one BRef, or several
// triangles of opened leaves. A BRef of a direct() placement becomes the child itself, triangles a leaf of the
// top level's own (after the objects' leaves, in world space), any other BRef an entry.
template <int N>
void pool_top_level(TwoLevelBvh<N>& bvh, const WideNodes<N>& top, const std::vector<LeafRun>& runs,
                    const std::vector<BRef>& brefs) {
    const uint32_t base = bvh.object_nodes;
    bvh.pool.nodes.resize(base);
    bvh.pool.nodes.insert(bvh.pool.nodes.end(), top.begin(), top.end());
    bvh.root = base;
    bvh.entries.clear();
    for (uint32_t i = base; i < bvh.pool.nodes.size(); ++i) {
        WideNode<N>& node = bvh.pool.nodes[i];
        for (int c = 0; c < N; ++c) {
            if (node.is_empty(c)) continue;
            if (!node.is_leaf(c)) {
                node.child[c] += base;
                continue;
            }
            const LeafRun& run = runs[node.child[c]];  // one entry a leaf: collapse numbers leaves in run order
            const BRef& r = brefs[run.first_ref];
            if (r.one_triangle()) {
                std::array<PlacedTriangle, kSweepUpTo> triangles;
                for (uint32_t t = 0; t < run.count; ++t) triangles[t] = world_triangle(bvh, brefs[run.first_ref + t]);
                node.child[c] = uint32_t(bvh.pool.leaves.size()), node.count[c] = run.count;
                append_leaf(bvh.pool.leaves, std::span<const PlacedTriangle>(triangles.data(), run.count));
            } else if (bvh.instances[r.instance].direct()) {
                node.child[c] = r.child, node.count[c] = r.count;
            } else {
                node.child[c] = uint32_t(bvh.entries.size()), node.count[c] = TwoLevelBvh<N>::kInstanceEntries | 1;
                bvh.entries.push_back({r.instance, r.child, r.count});
            }
        }
    }
    bvh.brefs = 0;
    for (const LeafRun& run : runs) bvh.brefs += run.count;
    // Traversal prefetches pool.leaves[child] for every leaf child it pushes, an entry's too: such an index stays
    // inside the leaf array even in a scene with more entries than object leaves (the padding is never read).
    if (bvh.pool.leaves.size() < bvh.entries.size()) bvh.pool.leaves.resize(bvh.entries.size(), LeafOf<N>{});
}

}  // namespace

template <int N>
uint64_t TwoLevelBvh<N>::bytes() const {
    return pool.bytes() + entries.size() * sizeof(TopLevelRef) + instances.size() * sizeof(PlacedObject);
}

template <int N>
void build_top_level(TwoLevelBvh<N>& bvh, const std::vector<TwoLevelInstance>& instances, const TwoLevelSettings& settings) {
    bvh.instances.resize(instances.size());
    bvh.to_world.resize(instances.size());
    for (size_t i = 0; i < instances.size(); ++i)
        bvh.instances[i] = place(instances[i], bvh.objects[instances[i].object]), bvh.to_world[i] = instances[i].to_world;
    bvh.pool.nodes.resize(bvh.object_nodes);
    bvh.pool.leaves.resize(bvh.object_leaves);
    bvh.entries.clear();
    bvh.brefs = 0;
    bvh.bounds = BBox{};
    if (instances.empty()) return;
    if (settings.bins < 2 || settings.bins > kMaxTopLevelBins)
        throw std::invalid_argument("top-level bins must be 2 to " + std::to_string(kMaxTopLevelBins) + ", not " +
                                    std::to_string(settings.bins));
    TopLevelSearch<N> search(bvh, instances, settings);
    const Bvh top = search.build();
    bvh.bounds = top.nodes[0].bounds;
    // At the world origin: the frame of the object trees the world ray reaches directly (build_two_level).
    bvh.pool.frame = PlaneFrame::at(Vec3(0.0f), bvh.bounds);
    WideNodes<N> nodes;
    uint32_t entries = 0;
    const std::vector<LeafRun> runs = collapse_nodes<N>(top, nodes, bvh.pool.frame, &one_entry_per_leaf, entries, settings.collapse);
    pool_top_level(bvh, nodes, runs, search.brefs());
}

template <int N>
TwoLevelBvh<N> build_two_level(const TwoLevelInput& input, const TwoLevelSettings& settings, TwoLevelTimes* times) {
    TwoLevelBvh<N> bvh;
    const BuilderEntry& builder = find_builder(settings.blas_builder);
    const auto start = Clock::now();
    const std::vector<uint32_t> bases = prim_bases(input);
    std::vector<bool> identity_placed(input.objects.size(), false);
    for (const TwoLevelInstance& instance : input.instances)
        if (instance.to_world == glm::mat4(1.0f)) identity_placed[instance.object] = true;
    bvh.objects.resize(input.objects.size());
    std::vector<WideBvh<N>> trees(input.objects.size());
    parallel::for_each(input.objects.size(), 1, [&](size_t i) {
        const std::vector<Triangle>& triangles = input.objects[i];
        bvh.objects[i].triangles = uint32_t(triangles.size());
        bvh.objects[i].prim_base = bases[i];
        if (triangles.empty()) return;
        const Bvh object = builder.build(BuildInput{triangles, make_prim_refs(triangles)}, settings.blas);
        // An object placed as it is shares the world ray with the top level, whose frame is at the world origin;
        // any other gets a frame at its centre, which the ray entering it is translated to.
        trees[i] = collapse<N>(object, triangles, settings.collapse,
                               identity_placed[i] ? std::optional<Vec3>(Vec3(0.0f)) : std::nullopt);
        bvh.objects[i].bounds = trees[i].bounds;
        bvh.objects[i].frame = trees[i].frame;
    });
    // A wide top level over at most one BRef per capacity slot has fewer nodes than slots (or one node).
    pool_object_trees(bvh, trees, bref_capacity(bvh.objects, input.instances, settings));
    if (times) times->objects_ms = ms_since(start);
    rebuild_top_level(bvh, input, settings, times);
    return bvh;
}

template <int N>
void rebuild_top_level(TwoLevelBvh<N>& bvh, const TwoLevelInput& input, const TwoLevelSettings& settings,
                       TwoLevelTimes* times) {
    const auto start = Clock::now();
    std::vector<TwoLevelInstance> placed;  // instances of empty objects have nothing to trace
    for (const TwoLevelInstance& instance : input.instances)
        if (!input.objects[instance.object].empty()) placed.push_back(instance);
    build_top_level(bvh, placed, settings);
    if (times) times->top_level_ms = ms_since(start);
}

namespace {


// The cost below one entry into an instance's object tree whose world box is `box`: C_tri per triangle of a
// leaf, C_inn per node, each box transformed to world space.
template <int N>
double entry_cost(const TwoLevelBvh<N>& bvh, const TopLevelRef& entry, const BBox& box, SahCosts costs) {
    if (entry.count) return costs.triangle * double(entry.count) * box.half_area();
    const WideNode<N>& node = bvh.pool.nodes[entry.child];
    double sum = costs.inner * box.half_area();
    for (int c = 0; c < N; ++c) {
        if (node.is_empty(c)) continue;
        const BBox local = bvh.objects[bvh.instances[entry.instance].object].frame.box(node, c);
        const BBox world = bvh.instances[entry.instance].identity ? local : transform_bounds(bvh.to_world[entry.instance], local);
        sum += entry_cost(bvh, {entry.instance, node.child[c], node.count[c]}, world, costs);
    }
    return sum;
}

// The cost below a node of the pool reached with the world ray: a top-level node or an object node linked
// directly, whose boxes are world boxes.
template <int N>
double world_cost(const TwoLevelBvh<N>& bvh, uint32_t index, const BBox& box, SahCosts costs) {
    const WideNode<N>& node = bvh.pool.nodes[index];
    double sum = costs.inner * box.half_area();
    for (int c = 0; c < N; ++c) {
        if (node.is_empty(c)) continue;
        const BBox child = bvh.pool.frame.box(node, c);
        if (!node.is_leaf(c)) {
            sum += world_cost(bvh, node.child[c], child, costs);
        } else if (node.count[c] & TwoLevelBvh<N>::kInstanceEntries) {
            const uint32_t first = node.child[c], end = first + (node.count[c] & ~TwoLevelBvh<N>::kInstanceEntries);
            for (uint32_t i = first; i < end; ++i) sum += entry_cost(bvh, bvh.entries[i], child, costs);
        } else {
            sum += costs.triangle * double(node.count[c]) * child.half_area();
        }
    }
    return sum;
}

}  // namespace

template <int N>
double sah_cost(const TwoLevelBvh<N>& bvh, SahCosts costs) {
    const double root = bvh.bounds.half_area();
    return bvh.brefs == 0 || !(root > 0.0) ? 0.0 : world_cost(bvh, bvh.root, bvh.bounds, costs) / root;
}

template double sah_cost<2>(const TwoLevelBvh<2>&, SahCosts);
template double sah_cost<4>(const TwoLevelBvh<4>&, SahCosts);
template double sah_cost<8>(const TwoLevelBvh<8>&, SahCosts);
template struct TwoLevelBvh<2>;
template struct TwoLevelBvh<4>;
template struct TwoLevelBvh<8>;
template TwoLevelBvh<2> build_two_level<2>(const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);
template TwoLevelBvh<4> build_two_level<4>(const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);
template TwoLevelBvh<8> build_two_level<8>(const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);
template void build_top_level<2>(TwoLevelBvh<2>&, const std::vector<TwoLevelInstance>&, const TwoLevelSettings&);
template void build_top_level<4>(TwoLevelBvh<4>&, const std::vector<TwoLevelInstance>&, const TwoLevelSettings&);
template void build_top_level<8>(TwoLevelBvh<8>&, const std::vector<TwoLevelInstance>&, const TwoLevelSettings&);
template void rebuild_top_level<2>(TwoLevelBvh<2>&, const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);
template void rebuild_top_level<4>(TwoLevelBvh<4>&, const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);
template void rebuild_top_level<8>(TwoLevelBvh<8>&, const TwoLevelInput&, const TwoLevelSettings&, TwoLevelTimes*);

}  // namespace canopy
