#include "accel/builders/binned_sah.h"

#include "accel/sah_binning.h"
#include "accel/sparse_tree.h"

namespace canopy {
namespace {

using namespace sah_binning;

constexpr size_t kParallelSubtreeGrain = 4 * 1024;

struct Range {
    uint32_t begin, end;
    Box4 bounds, centroids;  // centroids of doubled centres (PrimRef::center2)
    uint32_t size() const { return end - begin; }
};

class BinnedSahBuilder {
public:
    BinnedSahBuilder(std::vector<PrimRef>& refs, const BuildSettings& settings)
        : refs_(refs), settings_(settings), bins_(std::clamp<uint32_t>(settings.bins, 2, kMaxBins)),
          max_leaf_(std::max<uint32_t>(settings.max_leaf_size, 1)), nodes_(refs.size()) {}

    Bvh build(const Range& root) {
        build_subtree(root, 0, 1, 0);
        Bvh bvh;
        bvh.refs.resize(refs_.size());
        parallel::for_each(refs_.size(), 64 * 1024, [&](size_t i) { bvh.refs[i] = refs_[i].prim; });
        bvh.nodes = nodes_.finish();
        return bvh;
    }

private:
    // Builds the subtree over `range` rooted at slot `node`, its descendants from slot `descendants` on (slots as
    // SparseTree reserves them); returns how far past `descendants` its descendants reach.
    uint32_t build_subtree(const Range& range, uint32_t node, uint32_t descendants, uint32_t depth) {
        const uint32_t n = range.size();
        if (n > 1 && !leaf_always_cheaper(n) && depth < kMedianFallbackDepth && spread(range.centroids) > 0.0f) {
            const BinMapping mapping(range.centroids, object_bin_count(bins_, n));
            const Split split = best_split(bin_refs(refs_.data(), range.begin, range.size(), mapping), mapping.bins, settings_);
            const float area = range.bounds.half_area();
            const float split_cost = settings_.costs.inner * area + settings_.costs.triangle * split.cost;
            const bool leaf_is_cheaper = n <= max_leaf_ && settings_.costs.triangle * settings_.leaf_tests(n) * area <= split_cost;
            if (split.axis >= 0 && !leaf_is_cheaper) return partition(range, mapping, split, node, descendants, depth);
        }
        if (n <= max_leaf_) return nodes_.set_leaf(node, range.bounds.bbox(), range.begin, n);
        return split_at_median(range, node, descendants, depth);  // coincident centroids, or too deep
    }

    // Whether a leaf of n references beats every split without binning them: a leaf that one block test covers
    // costs C_tri A, and a split at least C_inn A plus its children's tests, so the leaf wins (ties go to leaves)
    // wherever C_inn >= C_tri. Most of a tree's nodes are that small.
    bool leaf_always_cheaper(uint32_t n) const {
        return n <= max_leaf_ && settings_.leaf_tests(n) <= 1.0f && settings_.costs.inner >= settings_.costs.triangle;
    }

    static float spread(const Box4& b) {
        alignas(16) float e[4];
        _mm_store_ps(e, _mm_sub_ps(b.upper, b.lower));
        return e[0] + e[1] + e[2];
    }

    // Hoare partition by bin; the children's centroid bounds are gathered on the way.
    uint32_t partition(const Range& range, const BinMapping& mapping, const Split& split, uint32_t node,
                       uint32_t descendants, uint32_t depth) {
        PrimRef* refs = refs_.data();
        uint32_t l = range.begin, r = range.end;
        Box4 left_centroids = Box4::empty(), right_centroids = Box4::empty();
        const BinMapping::Plane plane = mapping.plane(split.axis, split.bin);
        auto goes_left = [&](uint32_t i) { return plane.left_of(refs[i]); };
        for (;;) {
            while (l < r && goes_left(l)) left_centroids.extend(center2(refs[l++]));
            while (l < r && !goes_left(r - 1)) right_centroids.extend(center2(refs[--r]));
            if (l == r) break;
            std::swap(refs[l], refs[r - 1]);
            left_centroids.extend(center2(refs[l++]));
            right_centroids.extend(center2(refs[--r]));
        }
        return emit_children({range.begin, l, split.left, left_centroids}, {l, range.end, split.right, right_centroids},
                             range, node, descendants, depth);
    }

    uint32_t split_at_median(const Range& range, uint32_t node, uint32_t descendants, uint32_t depth) {
        const uint32_t mid = range.begin + range.size() / 2;
        return emit_children(bounds_of(range.begin, mid), bounds_of(mid, range.end), range, node, descendants, depth);
    }

    Range bounds_of(uint32_t begin, uint32_t end) const {
        Range r{begin, end, Box4::empty(), Box4::empty()};
        for (uint32_t i = begin; i < end; ++i) {
            r.bounds.extend(Box4::of(refs_[i]));
            r.centroids.extend(center2(refs_[i]));
        }
        return r;
    }

    uint32_t emit_children(const Range& left, const Range& right, const Range& parent, uint32_t node,
                           uint32_t descendants, uint32_t depth) {
        return nodes_.set_inner(
            node, parent.bounds.bbox(), descendants, left.size(), parent.size(), kParallelSubtreeGrain,
            [&](uint32_t first) { return build_subtree(left, descendants, first, depth + 1); },
            [&](uint32_t first) { return build_subtree(right, descendants + 1, first, depth + 1); });
    }

    std::vector<PrimRef>& refs_;
    const BuildSettings& settings_;
    const uint32_t bins_, max_leaf_;
    SparseTree nodes_;
};

}  // namespace

Bvh build_binned_sah(BuildInput&& input, const BuildSettings& settings) {
    require_power_of_two_block(settings);
    if (input.refs.empty()) return {};
    auto bounds = [&](size_t begin, size_t end) {
        std::pair<Box4, Box4> acc{Box4::empty(), Box4::empty()};
        for (size_t i = begin; i < end; ++i) {
            acc.first.extend(Box4::of(input.refs[i]));
            acc.second.extend(center2(input.refs[i]));
        }
        return acc;
    };
    auto join = [](std::pair<Box4, Box4> a, const std::pair<Box4, Box4>& b) {
        a.first.extend(b.first);
        a.second.extend(b.second);
        return a;
    };
    const auto [box, centroids] = parallel::reduce(input.refs.size(), kParallelGrain,
                                                   std::pair{Box4::empty(), Box4::empty()}, bounds, join);
    BinnedSahBuilder builder(input.refs, settings);
    return builder.build({0, uint32_t(input.refs.size()), box, centroids});
}

}  // namespace canopy
