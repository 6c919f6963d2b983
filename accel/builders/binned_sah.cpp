#include "accel/builders/binned_sah.h"

#include "accel/sah_binning.h"
#include "accel/top_down_builder.h"

namespace canopy {
namespace {

using namespace sah_binning;

constexpr size_t kParallelSubtreeGrain = 4 * 1024;

// Binned SAH over the references' centroids (accel/sah_binning.h), for TopDownBuilder.
class BinnedSahSearch {
public:
    struct Node {
        uint32_t begin, end;
        Box4 bounds, centroids;  // centroids of doubled centres (PrimRef::center2)
    };
    struct Split {
        BinMapping mapping;
        sah_binning::Split best;
        float cost;
        bool found() const { return best.axis >= 0; }
    };
    using Children = std::pair<Node, Node>;

    BinnedSahSearch(std::vector<PrimRef>& refs, const BuildSettings& settings)
        : refs_(refs), settings_(settings), bins_(std::clamp<uint32_t>(settings.bins, 2, kMaxBins)),
          max_leaf_(std::max<uint32_t>(settings.max_leaf_size, 1)) {}

    void prepare(Node&) const {}
    static uint32_t count(const Node& node) { return node.end - node.begin; }
    static uint32_t first(const Node& node) { return node.begin; }
    static uint32_t slots(const Node& node) { return count(node); }
    static BBox box(const Node& node) { return node.bounds.bbox(); }
    static float half_area(const Node& node) { return node.bounds.half_area(); }

    // Whether a leaf of n references beats every split without binning them: a leaf that one block test covers
    // costs C_tri A, and a split at least C_inn A plus its children's tests, so the leaf wins (ties go to leaves)
    // wherever C_inn >= C_tri; and coincident centroids leave nothing to bin. Most of a tree's nodes are that small.
    bool leaf_without_search(const Node& node) const {
        const uint32_t n = count(node);
        return n <= max_leaf_ && settings_.leaf_tests(n) <= 1.0f && settings_.costs.inner >= settings_.costs.triangle;
    }

    Split find(const Node& node) const {
        const uint32_t n = count(node);
        const BinMapping mapping(node.centroids, object_bin_count(bins_, n));
        if (!(spread(node.centroids) > 0.0f)) return {mapping, sah_binning::Split{}, 0.0f};
        const sah_binning::Split best = best_split(bin_refs(refs_.data(), node.begin, n, mapping), mapping.bins, settings_);
        return {mapping, best, best.cost};
    }

    // Hoare partition by bin; the children's centroid bounds are gathered on the way.
    std::optional<Children> split(const Node& node, const Split& chosen) {
        PrimRef* refs = refs_.data();
        uint32_t l = node.begin, r = node.end;
        Box4 left_centroids = Box4::empty(), right_centroids = Box4::empty();
        const BinMapping::Plane plane = chosen.mapping.plane(chosen.best.axis, chosen.best.bin);
        auto goes_left = [&](uint32_t i) { return plane.left_of(refs[i]); };
        for (;;) {
            while (l < r && goes_left(l)) left_centroids.extend(center2(refs[l++]));
            while (l < r && !goes_left(r - 1)) right_centroids.extend(center2(refs[--r]));
            if (l == r) break;
            std::swap(refs[l], refs[r - 1]);
            left_centroids.extend(center2(refs[l++]));
            right_centroids.extend(center2(refs[--r]));
        }
        return Children{{node.begin, l, chosen.best.left, left_centroids}, {l, node.end, chosen.best.right, right_centroids}};
    }

    // Coincident centroids, or too deep: the halves of the range as it lies.
    Children median(const Node& node) const {
        const uint32_t mid = node.begin + count(node) / 2;
        return {bounds_of(node.begin, mid), bounds_of(mid, node.end)};
    }

private:
    static float spread(const Box4& b) {
        alignas(16) float e[4];
        _mm_store_ps(e, _mm_sub_ps(b.upper, b.lower));
        return e[0] + e[1] + e[2];
    }

    Node bounds_of(uint32_t begin, uint32_t end) const {
        Node node{begin, end, Box4::empty(), Box4::empty()};
        for (uint32_t i = begin; i < end; ++i) {
            node.bounds.extend(Box4::of(refs_[i]));
            node.centroids.extend(center2(refs_[i]));
        }
        return node;
    }

    std::vector<PrimRef>& refs_;
    const BuildSettings& settings_;
    const uint32_t bins_, max_leaf_;
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
    BinnedSahSearch search(input.refs, settings);
    const TopDownLimits limits{std::max<uint32_t>(settings.max_leaf_size, 1), kMedianFallbackDepth, kParallelSubtreeGrain};
    TopDownBuilder<BinnedSahSearch> builder(search, settings, limits, input.refs.size());
    Bvh bvh;
    bvh.nodes = builder.build({0, uint32_t(input.refs.size()), box, centroids});
    bvh.refs.resize(input.refs.size());
    parallel::for_each(input.refs.size(), 64 * 1024, [&](size_t i) { bvh.refs[i] = input.refs[i].prim; });
    return bvh;
}

}  // namespace canopy
