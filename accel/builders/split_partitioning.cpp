#include "accel/builders/split_partitioning.h"

#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <stdexcept>

namespace canopy {
namespace {

constexpr double kRegionPadding = 1.2;           // sec. 4.1: a moved partition gets 20% extra space
constexpr size_t kParallelCutGrain = 16 * 1024;  // partitions at least this large are cut concurrently
constexpr size_t kParallelRefGrain = 8 * 1024;   // data-parallel bounds and clipping over this many refs

// A partition in memory: `size` refs at `base`, followed by free space up to `capacity`.
struct Region {
    PrimRef* base;
    uint32_t size, capacity;
};

struct Cut {
    int axis;
    float doubled_position;  // compared against PrimRef::center2, so the sides match the mid-point test exactly
    float position() const { return 0.5f * doubled_position; }
};

// One side of a cut after the in-place partition: its disjoint refs D and overlap refs O (sec. 3.2), the latter
// tracked by position rather than copied (sec. 4.1).
struct Side {
    BBox disjoint, overlap;
    uint32_t disjoint_count = 0;
    std::vector<uint32_t> overlaps;

    BBox bounds() const { return merge(disjoint, overlap); }
    uint32_t size() const { return disjoint_count + uint32_t(overlaps.size()); }
};

// The clipped halves of every overlap ref of one side, and the bounds and counts of S_L and S_R.
struct SplitSets {
    std::vector<std::pair<BBox, BBox>> pieces;  // by overlap, left piece and right piece
    BBox left, right;
    uint32_t left_count = 0, right_count = 0;
    uint32_t both = 0;  // refs cut into two non-empty halves: each adds one reference
};

PrimRef with_bounds(const PrimRef& ref, const BBox& bounds) {
    return {bounds.lower, ref.prim, bounds.upper, ref.reserved};
}

// Moves the block of `count` refs at `first` up by `distance`. Order inside a partition does not matter, so only
// the first min(distance, count) refs move, to the block's end (sec. 4.1: "a small segment ... is moved").
void shift_block(PrimRef* first, uint32_t count, uint32_t distance) {
    const uint32_t moved = std::min(distance, count);
    std::copy(first, first + moved, first + count + distance - moved);
}

class SplitPartitioner {
public:
    SplitPartitioner(std::span<const Triangle> triangles, uint32_t threshold, bool split, Partitioning& out)
        : triangles_(triangles), threshold_(std::max<uint32_t>(threshold, 1)), split_(split), out_(out) {}

    // `spare`: the PrimRef slots that this partition's subtree may still allocate in new regions (moved partitions).
    std::vector<std::span<PrimRef>> partition(Region region, uint64_t spare) {
        if (region.size <= threshold_) return {std::span(region.base, region.size)};
        const BBox centroids = centroid_bounds(region);
        const int axis = centroids.largest_axis();
        // Sec. 3.2: the spatial median of the mid-point bounds, on their largest axis.
        const Cut cut{axis, centroids.lower[axis] + 0.5f * (centroids.upper[axis] - centroids.lower[axis])};
        Side left, right;
        const uint32_t middle = partition_in_place(region, cut, left, right);
        if (middle == 0 || middle == region.size) return {std::span(region.base, region.size)};  // coincident
        SplitSets from_left, from_right;
        bool use_halves = false;
        if (split_ && !(left.overlaps.empty() && right.overlaps.empty())) {
            from_left = clip_overlaps(region, cut, left);
            from_right = clip_overlaps(region, cut, right);
            use_halves = split_is_cheaper(left, right, from_left, from_right) &&
                         moved_capacity(region, right, from_left, from_right) <= spare;
        }
        if (use_halves) spare -= moved_capacity(region, right, from_left, from_right);
        const auto [left_region, right_region] = use_halves
                                                     ? replace_overlaps(region, left, right, from_left, from_right)
                                                     : rebalance(region, middle, region.size - middle, 0, 0);
        // The spare slots are shared in proportion to the sides' sizes: the same at any thread count.
        const uint64_t left_spare = spare * left_region.size / (uint64_t(left_region.size) + right_region.size);
        std::vector<std::span<PrimRef>> left_parts, right_parts;
        parallel::fork_join(
            region.size, kParallelCutGrain, [&, l = left_region] { left_parts = partition(l, left_spare); },
            [&, r = right_region] { right_parts = partition(r, spare - left_spare); });
        left_parts.insert(left_parts.end(), right_parts.begin(), right_parts.end());
        return left_parts;
    }

    PrimRef* allocate(uint32_t capacity) {
        std::lock_guard lock(mutex_);
        out_.regions.push_back(std::make_unique<PrimRef[]>(capacity));
        out_.reference_capacity += capacity;
        return out_.regions.back().get();
    }

private:
    // Doubled mid-points, as the cut compares them.
    static BBox centroid_bounds(const Region& region) {
        return parallel::reduce(
            region.size, kParallelRefGrain, BBox{},
            [&](size_t begin, size_t end) {
                BBox b;
                for (size_t i = begin; i < end; ++i) b.extend(region.base[i].center2());
                return b;
            },
            [](BBox a, const BBox& b) { return merge(a, b); });
    }

    // Quick-sort style partition with the plane as pivot (sec. 4.1); overlap refs stay where their mid-point puts
    // them and their positions are recorded. Returns the size of the left side.
    static uint32_t partition_in_place(const Region& region, const Cut& cut, Side& left, Side& right) {
        PrimRef* refs = region.base;
        const float plane = cut.position();
        auto goes_left = [&](uint32_t i) { return refs[i].center2()[cut.axis] < cut.doubled_position; };
        auto take = [&](Side& side, uint32_t i) {
            if (refs[i].lower[cut.axis] < plane && refs[i].upper[cut.axis] > plane) {
                side.overlap.extend(refs[i].bounds());
                side.overlaps.push_back(i);
            } else {
                side.disjoint.extend(refs[i].bounds());
                ++side.disjoint_count;
            }
        };
        uint32_t l = 0, r = region.size;
        for (;;) {
            while (l < r && goes_left(l)) take(left, l++);
            while (l < r && !goes_left(r - 1)) take(right, --r);
            if (l == r) return l;
            std::swap(refs[l], refs[r - 1]);
            take(left, l++);
            take(right, --r);
        }
    }

    // Sec. 3.2: C_O against C_S. Clipping each overlap triangle against the plane gives S_L and S_R; the split
    // halves are kept when A(D_L u S_L)|D_L u S_L| + A(D_R u S_R)|D_R u S_R| is below the same with O_L, O_R.
    static bool split_is_cheaper(const Side& left, const Side& right, const SplitSets& from_left,
                                 const SplitSets& from_right) {
        const BBox split_left = merge(merge(left.disjoint, from_left.left), from_right.left);
        const BBox split_right = merge(merge(right.disjoint, from_left.right), from_right.right);
        const uint32_t split_left_count = left.disjoint_count + from_left.left_count + from_right.left_count;
        const uint32_t split_right_count = right.disjoint_count + from_left.right_count + from_right.right_count;
        const float c_o = left.bounds().half_area() * float(left.size()) + right.bounds().half_area() * float(right.size());
        const float c_s = split_left.half_area() * float(split_left_count) + split_right.half_area() * float(split_right_count);
        return c_s < c_o;
    }

    SplitSets clip_overlaps(const Region& region, const Cut& cut, const Side& side) const {
        SplitSets sets;
        sets.pieces.resize(side.overlaps.size());
        parallel::for_each(side.overlaps.size(), kParallelRefGrain, [&](size_t k) {
            const PrimRef& ref = region.base[side.overlaps[k]];
            sets.pieces[k] = split_triangle_bounds(triangles_[ref.prim], ref.bounds(), cut.axis, cut.position());
        });
        for (const auto& [l, r] : sets.pieces) {
            if (!l.empty()) sets.left.extend(l), ++sets.left_count;
            if (!r.empty()) sets.right.extend(r), ++sets.right_count;
            sets.both += !l.empty() && !r.empty();
        }
        return sets;
    }

    // The slots replace_overlaps allocates for the right side when the halves outgrow the region, else 0.
    static uint64_t moved_capacity(const Region& region, const Side& right, const SplitSets& from_left,
                                   const SplitSets& from_right) {
        if (uint64_t(region.size) + from_left.both + from_right.both <= region.capacity) return 0;
        return uint64_t(std::ceil((right.size() + from_left.both) * kRegionPadding));
    }

    // Sec. 4.1: each overlap ref is replaced in place by its half on its own side; the other half joins the other
    // side. The right side moves up to make room for the left's new halves, or to a new region when the free space
    // behind the partition does not hold both.
    std::pair<Region, Region> replace_overlaps(const Region& region, const Side& left, const Side& right,
                                               const SplitSets& from_left, const SplitSets& from_right) {
        std::vector<PrimRef> to_left, to_right;
        place_halves(region, left.overlaps, from_left, true, to_right);
        place_halves(region, right.overlaps, from_right, false, to_left);
        const uint32_t left_size = left.size(), right_size = right.size();
        const uint32_t grown = region.size + uint32_t(to_left.size() + to_right.size());
        if (grown > region.capacity) {
            const uint32_t moved_size = right_size + uint32_t(to_right.size());
            const uint32_t capacity = uint32_t(std::ceil(moved_size * kRegionPadding));
            PrimRef* moved = allocate(capacity);
            std::copy(region.base + left_size, region.base + region.size, moved);
            std::copy(to_right.begin(), to_right.end(), moved + right_size);
            std::copy(to_left.begin(), to_left.end(), region.base + left_size);
            return {{region.base, left_size + uint32_t(to_left.size()), region.capacity}, {moved, moved_size, capacity}};
        }
        const auto [l, r] = rebalance(region, left_size, right_size, uint32_t(to_left.size()), uint32_t(to_right.size()));
        std::copy(to_left.begin(), to_left.end(), region.base + left_size);
        std::copy(to_right.begin(), to_right.end(), r.base + right_size);
        return {l, r};
    }

    // Writes each overlap ref's own-side half in place and collects the other halves for the other side.
    static void place_halves(const Region& region, const std::vector<uint32_t>& overlaps, const SplitSets& sets,
                             bool on_left, std::vector<PrimRef>& other_side) {
        for (size_t k = 0; k < overlaps.size(); ++k) {
            PrimRef& ref = region.base[overlaps[k]];
            const auto& [l, r] = sets.pieces[k];
            const BBox& own = on_left ? l : r;
            const BBox& other = on_left ? r : l;
            if (own.empty() && other.empty()) continue;  // cannot happen for a straddling triangle; keep it whole
            const PrimRef original = ref;
            ref = with_bounds(original, own.empty() ? other : own);
            if (!own.empty() && !other.empty()) other_side.push_back(with_bounds(original, other));
        }
    }

    // Sec. 4.1: the free space is shared out in proportion to the sides' sizes. The right side (at `left_size` now)
    // moves up by the left side's growth and its share; the left side's new refs are then written by the caller.
    static std::pair<Region, Region> rebalance(const Region& region, uint32_t left_size, uint32_t right_size,
                                               uint32_t left_growth, uint32_t right_growth) {
        const uint32_t left_total = left_size + left_growth, right_total = right_size + right_growth;
        const uint64_t free = region.capacity - left_total - right_total;
        const uint32_t left_free = uint32_t(free * left_total / (left_total + right_total));
        const uint32_t right_start = left_total + left_free;
        shift_block(region.base + left_size, right_size, right_start - left_size);
        return {{region.base, left_total, right_start}, {region.base + right_start, right_total, region.capacity - right_start}};
    }

    std::span<const Triangle> triangles_;
    const uint32_t threshold_;
    const bool split_;
    Partitioning& out_;
    std::mutex mutex_;
};

}  // namespace

uint32_t split_partition_threshold(size_t primitives) {
    constexpr double kSmall = 100'000, kLarge = 4'000'000, kMin = 512, kMax = 8192;
    const double t = std::clamp((double(primitives) - kSmall) / (kLarge - kSmall), 0.0, 1.0);
    return uint32_t(kMin + t * (kMax - kMin));
}

size_t Partitioning::reference_count() const {
    size_t n = 0;
    for (const auto& p : partitions) n += p.size();
    return n;
}

Partitioning partition_refs(std::span<const Triangle> triangles, std::span<const PrimRef> refs, uint32_t threshold,
                            bool split) {
    if (threshold == 0) throw std::invalid_argument("split partitioning: the partition threshold must be at least 1");
    Partitioning out;
    SplitPartitioner partitioner(triangles, threshold, split, out);
    // Split partitioning appends halves behind the first partition, so it starts with the same 20% of room.
    const uint32_t n = uint32_t(refs.size());
    const uint32_t capacity = split ? uint32_t(std::ceil(n * kRegionPadding)) : n;
    PrimRef* root = partitioner.allocate(std::max<uint32_t>(capacity, 1));
    parallel::for_each(n, 64 * 1024, [&](size_t i) { root[i] = refs[i]; });
    // At most kMaxReferenceCapacity slots in all: the splits that would need more are not made.
    const auto limit = uint64_t(kMaxReferenceCapacity * double(n));
    out.partitions = partitioner.partition({root, n, capacity}, limit > capacity ? limit - capacity : 0);
    return out;
}

std::vector<PrimRef> compact(const Partitioning& partitioning) {
    std::vector<size_t> offsets(partitioning.partitions.size() + 1, 0);
    for (size_t i = 0; i < partitioning.partitions.size(); ++i) offsets[i + 1] = offsets[i] + partitioning.partitions[i].size();
    std::vector<PrimRef> refs(offsets.back());
    parallel::for_each(partitioning.partitions.size(), 1, [&](size_t i) {
        std::copy(partitioning.partitions[i].begin(), partitioning.partitions[i].end(), refs.begin() + offsets[i]);
    });
    return refs;
}

}  // namespace canopy
