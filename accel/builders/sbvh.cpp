#include "accel/builders/sbvh.h"

#include "accel/parallel.h"
#include "accel/sah_binning.h"
#include "accel/spatial_binning.h"
#include "accel/top_down_builder.h"
#include "accel/triangle_clipping.h"

#include <array>
#include <cstdio>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

namespace canopy {
namespace {

using sah_binning::Box4;
using sah_binning::Box8;
using spatial_binning::AxisBins;
using spatial_binning::SpatialAxis;

// Spatial bins per axis. Clipping a reference into every bin it spans is the expensive part of SBVH: 12 bins on
// each of the three axes, as Stich et al. bin them, since the largest axis alone built faster but made trees that
// rays visit more of, for slower frames (docs/results.md#builds-and-layouts).
constexpr uint32_t kSpatialBins = spatial_binning::kMaxBins;
constexpr size_t kParallelBinningGrain = sah_binning::kParallelGrain;
constexpr size_t kParallelSubtreeGrain = 4 * 1024;

// References [begin, begin + count) of the shared array; the slots up to begin + capacity are this subtree's
// own, for the references its spatial splits add.
struct Extent {
    uint32_t begin, count, capacity;
};

struct Candidate {
    float cost = std::numeric_limits<float>::infinity();  // A_left T_left + A_right T_right (half areas, tests)
    int axis = -1;
    uint32_t plane = 0;  // object: refs in bins [0, plane) go left; spatial: the plane between bins plane-1, plane
    BBox left, right;
    uint32_t left_count = 0, right_count = 0;
};

struct NodeInfo {
    Box4 bounds, centroids;  // centroids of doubled centres (PrimRef::center2)
};

// Sweeps the planes between one axis's spatial bins: the left side holds the references that enter a bin left of
// the plane, the right side those that leave one right of it. Records a cheaper plane's cost, axis and plane only;
// spatial_sides fills in the winner's sides.
void sweep(const SpatialAxis& bins, uint32_t n, int axis, const sah_binning::LeafTests& tests, Candidate& best) {
    std::array<float, kSpatialBins> right_cost;
    std::array<uint32_t, kSpatialBins> right_n{};
    Box8 box = Box8::empty();
    uint32_t count = 0;
    for (uint32_t i = n; i-- > 1;) {
        box.extend(bins.bounds[i]);
        count += bins.exits[i];
        right_cost[i] = box.half_area() * tests(count);
        right_n[i] = count;
    }
    box = Box8::empty();
    count = 0;
    for (uint32_t i = 1; i < n; ++i) {
        box.extend(bins.bounds[i - 1]);
        count += bins.entries[i - 1];
        if (count == 0 || right_n[i] == 0) continue;
        const float cost = box.half_area() * tests(count) + right_cost[i];
        if (cost < best.cost) best.cost = cost, best.axis = axis, best.plane = i;
    }
}

// The boxes and reference counts of the sides of `split`, a plane found by sweep on these bins.
void spatial_sides(const SpatialAxis& bins, uint32_t n, Candidate& split) {
    Box8 left = Box8::empty(), right = Box8::empty();
    for (uint32_t i = 0; i < n; ++i) {
        if (i < split.plane) {
            left.extend(bins.bounds[i]);
            split.left_count += bins.entries[i];
        } else {
            right.extend(bins.bounds[i]);
            split.right_count += bins.exits[i];
        }
    }
    split.left = left.box4().bbox();
    split.right = right.box4().bbox();
}

// SBVH's search, for TopDownBuilder: the cheaper of the best binned object split and the best binned spatial split.
// Its spatial splits add references: a node owns the slots of its extent, and the references it adds go there.
class SbvhSearch {
public:
    struct Node {
        Extent e;
        NodeInfo info;  // filled in by prepare
    };
    struct Split {
        sah_binning::BinMapping mapping;  // of the object split
        Candidate object, spatial;
        bool use_spatial;
        float cost;  // the chosen candidate's
        bool found() const { return (use_spatial ? spatial : object).axis >= 0; }
    };
    using Children = std::pair<Node, Node>;

    SbvhSearch(std::span<const Triangle> triangles, std::vector<PrimRef>& refs, const BuildSettings& settings,
               const SbvhSettings& sbvh, float root_half_area)
        : triangles_(triangles), refs_(refs), settings_(settings),
          object_bins_(std::clamp<uint32_t>(settings.bins, 2, sah_binning::kMaxBins)),
          min_overlap_(sbvh.alpha * root_half_area) {}

    void prepare(Node& node) const { node.info = info_of(node.e); }
    static uint32_t count(const Node& node) { return node.e.count; }
    static uint32_t first(const Node& node) { return node.e.begin; }
    static uint32_t slots(const Node& node) { return node.e.capacity; }
    static BBox box(const Node& node) { return node.info.bounds.bbox(); }
    static float half_area(const Node& node) { return node.info.bounds.half_area(); }
    static bool leaf_without_search(const Node&) { return false; }

    Split find(const Node& node) const {
        const Extent& e = node.e;
        const uint32_t n = e.count;
        const sah_binning::BinMapping mapping(node.info.centroids, object_bins(n));
        Candidate object = best_object_split(e, mapping);
        Candidate spatial;
        // Stich et al.: spatial splits only where the object split leaves overlap, and only within the memory cap.
        BBox overlap = object.left;
        overlap.lower = glm::max(overlap.lower, object.right.lower);
        overlap.upper = glm::min(overlap.upper, object.right.upper);
        if (e.capacity > n && (object.axis < 0 || overlap.half_area() > min_overlap_)) spatial = best_spatial_split(e, box(node));
        const bool use_spatial = spatial.cost < object.cost && spatial.left_count + spatial.right_count - n <= e.capacity - n;
        const float cost = use_spatial ? spatial.cost : object.cost;
        return {mapping, object, spatial, use_spatial, cost};
    }

    // The spatial split where it leaves both sides references, else the object split, if any.
    std::optional<Children> split(const Node& node, const Split& chosen) {
        if (chosen.use_spatial) {
            if (auto children = split_spatially(node.e, chosen.spatial, box(node))) return children;
        }
        if (chosen.object.axis >= 0) return split_by_objects(node.e, chosen.object, chosen.mapping);
        return std::nullopt;
    }

    // Coincident centroids, or too deep: the halves of the extent as it lies.
    Children median(const Node& node) {
        const uint32_t half = node.e.count / 2;
        return children(node.e, half, node.e.count - half, true);
    }

private:
    NodeInfo info_of(const Extent& e) const {
        const NodeInfo none{Box4::empty(), Box4::empty()};
        auto chunk = [&](size_t b, size_t end) {
            Box4 bounds = Box4::empty(), centroids = Box4::empty();  // locals: GCC kept a NodeInfo in memory
            for (size_t i = e.begin + b; i < e.begin + end; ++i) {
                bounds.extend(Box4::of(refs_[i]));
                centroids.extend(sah_binning::center2(refs_[i]));
            }
            return NodeInfo{bounds, centroids};
        };
        auto join = [](NodeInfo a, const NodeInfo& b) {
            a.bounds.extend(b.bounds);
            a.centroids.extend(b.centroids);
            return a;
        };
        return parallel::reduce(e.count, kParallelBinningGrain, none, chunk, join);
    }

    // Binned SAH over the references' centroids, as the binned builder does (accel/sah_binning.h).
    uint32_t object_bins(uint32_t n) const { return sah_binning::object_bin_count(object_bins_, n); }

    Candidate best_object_split(const Extent& e, const sah_binning::BinMapping& mapping) const {
        const sah_binning::Split split =
            sah_binning::best_split(sah_binning::bin_refs(refs_.data(), e.begin, e.count, mapping), mapping.bins, settings_);
        if (split.axis < 0) return {};
        return {split.cost, split.axis, split.bin, split.left.bbox(), split.right.bbox(), split.left_count, split.right_count};
    }

    // Stich et al.: spatial bins over the node's bounds on each axis, a reference that spans several chopped into
    // them (accel/spatial_binning.h). The bins only price splits, so they are computed in float: exact clipping was
    // a large share of a build, and the trees came out the same (split_spatially clips references exactly;
    // docs/results.md#builds-and-layouts).
    // Small nodes get fewer: a bin per reference is enough.
    static uint32_t spatial_bins(uint32_t n) { return std::clamp<uint32_t>(n, 4, kSpatialBins); }

    Candidate best_spatial_split(const Extent& e, const BBox& bounds) const {
        using Axes = std::array<SpatialAxis, 3>;
        const uint32_t bins = spatial_bins(e.count);
        const std::array<AxisBins, 3> maps = {AxisBins(bounds.lower.x, bounds.upper.x, bins),
                                              AxisBins(bounds.lower.y, bounds.upper.y, bins),
                                              AxisBins(bounds.lower.z, bounds.upper.z, bins)};
        // AxisBins::bin on the three axes at once, in the same arithmetic, so that split_spatially's bins agree.
        const sah_binning::BinMapping mapping({spatial_binning::load_point(bounds.lower), spatial_binning::load_point(bounds.upper)}, bins);
        auto chunk = [&](size_t b, size_t end) {
            Axes axes;
            alignas(16) int32_t first[4], last[4];
            for (size_t i = e.begin + b; i < e.begin + end; ++i) {
                const PrimRef& ref = refs_[i];
                const __m256 lower_upper = _mm256_load_ps(&ref.lower.x);
                const Box4 piece{_mm256_castps256_ps128(lower_upper), _mm256_extractf128_ps(lower_upper, 1)};
                const Box8 piece8 = Box8::of(lower_upper);
                const __m128i f = mapping.bin3(piece.lower), l = mapping.bin3(piece.upper);
                _mm_store_si128(reinterpret_cast<__m128i*>(first), f);
                _mm_store_si128(reinterpret_cast<__m128i*>(last), l);
                const int same = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(f, l)));
                for (int axis = 0; axis < 3; ++axis) {
                    SpatialAxis& out = axes[axis];
                    if (same >> axis & 1) {  // most references, in all but the top levels: no clipping
                        out.bounds[first[axis]].extend(piece8);
                        ++out.entries[first[axis]];
                        ++out.exits[first[axis]];
                    } else {
                        spatial_binning::bin_chopped(triangles_[ref.prim], piece, axis, maps[axis], uint32_t(first[axis]), uint32_t(last[axis]), out);
                    }
                }
            }
            return axes;
        };
        auto join = [](Axes a, const Axes& b) {
            for (int axis = 0; axis < 3; ++axis) a[axis].add(b[axis]);
            return a;
        };
        const Axes axes = parallel::reduce_lazy(e.count, kParallelBinningGrain, [] { return Axes{}; }, chunk, join);
        const sah_binning::LeafTests tests(settings_);
        Candidate best;
        for (int axis = 0; axis < 3; ++axis)
            if (bounds.upper[axis] > bounds.lower[axis]) sweep(axes[axis], bins, axis, tests, best);
        if (best.axis >= 0) spatial_sides(axes[best.axis], bins, best);
        return best;
    }

    Children split_by_objects(const Extent& e, const Candidate& split, const sah_binning::BinMapping& mapping) {
        PrimRef* first = refs_.data() + e.begin;
        const sah_binning::BinMapping::Plane plane = mapping.plane(split.axis, split.plane);
        PrimRef* middle = std::partition(first, first + e.count, [&](const PrimRef& r) { return plane.left_of(r); });
        const auto left = uint32_t(middle - first);
        return children(e, left, e.count - left, true);
    }

    enum class Side : uint8_t { left, right, both };

    // Reference unsplitting (Stich et al.): a straddling reference goes whole to one side when that is cheaper
    // than splitting it (costs against the split's bins, so every reference is decided independently).
    Side place(const PrimRef& ref, const Candidate& split) const {
        const float tl = settings_.leaf_tests(split.left_count), tr = settings_.leaf_tests(split.right_count);
        const float al = split.left.half_area(), ar = split.right.half_area();
        const float both = al * tl + ar * tr;
        const float whole_left = merge(split.left, ref.bounds()).half_area() * tl + ar * settings_.leaf_tests(split.right_count - 1);
        const float whole_right = al * settings_.leaf_tests(split.left_count - 1) + merge(split.right, ref.bounds()).half_area() * tr;
        if (both <= whole_left && both <= whole_right) return Side::both;
        return whole_left <= whole_right ? Side::left : Side::right;
    }

    // Partitions into [left only | straddling | right only], clips or places the straddling references and lays
    // the two sides out in their extents. Returns the children, or nothing (refs only permuted) when a side would
    // come out empty.
    std::optional<Children> split_spatially(const Extent& e, const Candidate& split, const BBox& bounds) {
        const AxisBins map(bounds.lower[split.axis], bounds.upper[split.axis], spatial_bins(e.count));
        const float position = map.plane(split.plane);
        PrimRef* first = refs_.data() + e.begin;
        PrimRef* end = first + e.count;
        PrimRef* straddling = std::partition(first, end, [&](const PrimRef& r) { return map.bin(r.upper[split.axis]) < split.plane; });
        PrimRef* right_only = std::partition(straddling, end, [&](const PrimRef& r) { return map.bin(r.lower[split.axis]) < split.plane; });

        std::vector<PrimRef> to_left, to_right;
        for (const PrimRef* r = straddling; r != right_only; ++r) {
            Side side = place(*r, split);
            BBox left = r->bounds(), right = r->bounds();
            if (side == Side::both) {
                std::tie(left, right) = split_triangle_bounds(triangles_[r->prim], r->bounds(), split.axis, position);
                if (left.empty()) side = Side::right, right = r->bounds();
                else if (right.empty()) side = Side::left, left = r->bounds();
            }
            if (side != Side::right) to_left.push_back({left.lower, r->prim, left.upper});
            if (side != Side::left) to_right.push_back({right.lower, r->prim, right.upper});
        }
        const auto left_count = uint32_t((straddling - first) + to_left.size());
        const auto right_only_count = uint32_t(end - right_only);
        const auto right_count = uint32_t(right_only_count + to_right.size());
        if (left_count == 0 || right_count == 0 || left_count + right_count > e.capacity) return std::nullopt;

        const uint32_t right_begin = e.begin + left_count + left_share(e, left_count, right_count);
        std::move_backward(right_only, end, refs_.data() + right_begin + right_count);
        std::copy(to_right.begin(), to_right.end(), refs_.data() + right_begin);
        std::copy(to_left.begin(), to_left.end(), straddling);
        return children(e, left_count, right_count, false);
    }

    // The spare slots a subtree hands on, split in proportion to the children's references.
    static uint32_t left_share(const Extent& e, uint32_t left, uint32_t right) {
        const uint64_t spare = e.capacity - left - right;
        return uint32_t(spare * left / (uint64_t(left) + right));
    }

    // Children: the left side's references at e.begin, the right side's at the start of its extent, where
    // they are moved when they still follow the left side's. A subtree over an extent of c slots has at most c
    // leaves, so the 2c - 2 tree slots TopDownBuilder reserves for its descendants suffice.
    Children children(const Extent& e, uint32_t left, uint32_t right, bool right_follows_left) {
        const uint32_t left_capacity = left + left_share(e, left, right);
        const Extent le{e.begin, left, left_capacity};
        const Extent re{e.begin + left_capacity, right, e.capacity - left_capacity};
        if (right_follows_left) {  // object and median splits: move the right side up to its extent
            PrimRef* from = refs_.data() + e.begin + left;
            std::move_backward(from, from + right, refs_.data() + re.begin + right);
        }
        return {Node{le, {}}, Node{re, {}}};
    }

    std::span<const Triangle> triangles_;
    std::vector<PrimRef>& refs_;
    const BuildSettings& settings_;
    const uint32_t object_bins_;
    const float min_overlap_;
};

// The leaves' references sit in their subtrees' slots with gaps between; packs them, leaf by leaf.
Bvh pack_leaves(BvhNodes&& nodes, const std::vector<PrimRef>& refs) {
    Bvh bvh;
    bvh.nodes = std::move(nodes);
    for (BvhNode& node : bvh.nodes) {
        if (!node.is_leaf()) continue;
        const uint32_t first = uint32_t(bvh.refs.size());
        for (uint32_t i = node.index; i < node.index + node.count; ++i) bvh.refs.push_back(refs[i].prim);
        node.index = first;
    }
    return bvh;
}

}  // namespace

Bvh build_sbvh_with(BuildInput&& input, const BuildSettings& settings, const SbvhSettings& sbvh) {
    if (!(sbvh.alpha >= 0.0f) || !std::isfinite(sbvh.alpha))
        throw std::invalid_argument("sbvh: alpha must be finite and >= 0, got " + std::to_string(sbvh.alpha));
    if (!(sbvh.max_references_per_triangle >= 1.0f) || !std::isfinite(sbvh.max_references_per_triangle))
        throw std::invalid_argument("sbvh: max_references_per_triangle must be finite and >= 1, got " +
                                    std::to_string(sbvh.max_references_per_triangle));
    if (input.refs.empty()) return {};
    const auto triangles = uint32_t(input.refs.size());
    const double slots = std::floor(double(triangles) * double(sbvh.max_references_per_triangle));
    if (slots > double(std::numeric_limits<uint32_t>::max() / 2))
        throw std::invalid_argument("sbvh: " + std::to_string(triangles) + " triangles times the reference cap exceed 32-bit indices");
    BBox root;
    for (const PrimRef& r : input.refs) root.extend(r.bounds());
    input.refs.resize(size_t(slots));
    BuildSettings priced = settings;
    priced.leaf_block = std::max(sbvh.leaf_block, 1u);
    sah_binning::require_power_of_two_block(priced);
    SbvhSearch search(input.triangles, input.refs, priced, sbvh, root.half_area());
    const TopDownLimits limits{std::max<uint32_t>(settings.max_leaf_size, 1), kMedianFallbackDepth, kParallelSubtreeGrain};
    TopDownBuilder<SbvhSearch> builder(search, priced, limits, input.refs.size());
    Bvh bvh = pack_leaves(builder.build(SbvhSearch::Node{Extent{0, triangles, uint32_t(input.refs.size())}, NodeInfo{Box4::empty(), Box4::empty()}}), input.refs);
    // Spatial splitting is interleaved with partitioning, not a pass of its own, so no split time is reported;
    // the capacity is the reference array allocated up front.
    bvh.split = {0.0, uint64_t(slots)};
    return bvh;
}

float parse_sbvh_alpha(const std::string& text) {
    size_t used = 0;
    float alpha = -1.0f;
    try {
        alpha = std::stof(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (text.empty() || used != text.size() || !(alpha >= 0.0f) || !std::isfinite(alpha))
        throw std::invalid_argument("sbvh alpha '" + text + "': a share of the root's area, finite and >= 0");
    return alpha;
}

std::vector<BuilderParam> sbvh_params() {
    char default_text[32];
    std::snprintf(default_text, sizeof default_text, "%g", double(kSbvhAlpha));
    return {{"alpha", default_text,
             "spatial splits only where object splits overlap by more than this share of the root's area "
             "(Stich et al. 2009 and the quality-metrics paper: 1e-5)",
             [](const std::string& text) {
                 char canonical[32];
                 std::snprintf(canonical, sizeof canonical, "%g", double(parse_sbvh_alpha(text)));
                 return std::string(canonical);
             }}};
}

Bvh build_sbvh(BuildInput&& input, const BuildSettings& settings) {
    SbvhSettings sbvh;
    if (const std::string* alpha = settings.params.find("alpha")) sbvh.alpha = parse_sbvh_alpha(*alpha);
    return build_sbvh_with(std::move(input), settings, sbvh);
}

}  // namespace canopy
