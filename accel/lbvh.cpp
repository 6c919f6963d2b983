#include "accel/lbvh.h"

#include "accel/parallel.h"

#include <array>
#include <atomic>
#include <bit>
#include <utility>

namespace canopy {
namespace {

constexpr size_t kGrain = 16 * 1024;

// Spreads the low 21 bits of x to every third bit of a 63-bit code.
uint64_t spread_bits(uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x001f00000000ffffull;
    x = (x | x << 16) & 0x001f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
}

std::vector<uint64_t> morton_codes(const std::vector<PrimRef>& refs) {
    const BBox centroids = parallel::reduce(
        refs.size(), kGrain, BBox{},
        [&](size_t begin, size_t end) {
            BBox b;
            for (size_t i = begin; i < end; ++i) b.extend(refs[i].center2());
            return b;
        },
        [](BBox a, const BBox& b) { return merge(a, b); });
    const Vec3 extent = centroids.extent();
    Vec3 scale;
    for (int a = 0; a < 3; ++a) scale[a] = extent[a] > 0 ? float((1u << 21) - 1) / extent[a] : 0.0f;
    std::vector<uint64_t> codes(refs.size());
    parallel::for_each(refs.size(), kGrain, [&](size_t i) {
        const Vec3 q = (refs[i].center2() - centroids.lower) * scale;
        codes[i] = spread_bits(uint64_t(q.x)) << 2 | spread_bits(uint64_t(q.y)) << 1 | spread_bits(uint64_t(q.z));
    });
    return codes;
}

// Least-significant-digit radix sort of (code, index) pairs, 11 bits a pass (six passes cover 63 bits), each
// pass a parallel histogram, a prefix sum per chunk and a parallel stable scatter. Returns the indices in
// code order; stable, so equal codes keep index order and the result does not depend on threads.
std::vector<uint32_t> radix_sort(std::vector<uint64_t>& codes) {
    const size_t n = codes.size();
    const size_t chunks = std::max<size_t>(1, std::min<size_t>(64, n / kGrain));
    std::vector<uint32_t> order(n), next_order(n);
    std::vector<uint64_t> next_codes(n);
    for (uint32_t i = 0; i < n; ++i) order[i] = i;
    auto chunk_begin = [&](size_t c) { return n * c / chunks; };
    constexpr int kBits = 11;
    constexpr uint64_t kDigits = uint64_t(1) << kBits;
    for (int shift = 0; shift < 63; shift += kBits) {
        std::vector<std::array<uint32_t, kDigits>> counts(chunks);
        parallel::for_each(chunks, 1, [&](size_t c) {
            counts[c].fill(0);
            for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) ++counts[c][(codes[i] >> shift) & (kDigits - 1)];
        });
        uint32_t offset = 0;
        for (uint64_t digit = 0; digit < kDigits; ++digit)
            for (size_t c = 0; c < chunks; ++c) offset += std::exchange(counts[c][digit], offset);
        parallel::for_each(chunks, 1, [&](size_t c) {
            for (size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) {
                const uint32_t at = counts[c][(codes[i] >> shift) & (kDigits - 1)]++;
                next_codes[at] = codes[i];
                next_order[at] = order[i];
            }
        });
        codes.swap(next_codes);
        order.swap(next_order);
    }
    return order;
}

// Karras 2012, sec. 4: inner node i covers a range of sorted leaves, one end of which is i; its split is
// where the common prefix of the codes drops. Equal codes are told apart by their positions (sec. 4, last
// paragraph), so every code is distinct.
class KarrasHierarchy {
public:
    explicit KarrasHierarchy(const std::vector<uint64_t>& codes) : codes_(codes), n_(int64_t(codes.size())) {}

    struct Inner {
        uint32_t left, right;  // child ids: below n - 1 an inner node, else leaf (id - (n - 1))
    };

    Inner node(int64_t i) const {
        const int d = delta(i, i + 1) > delta(i, i - 1) ? 1 : -1;
        const int delta_min = delta(i, i - d);
        int64_t l_max = 2;
        while (delta(i, i + l_max * d) > delta_min) l_max *= 2;
        int64_t l = 0;
        for (int64_t t = l_max / 2; t >= 1; t /= 2)
            if (delta(i, i + (l + t) * d) > delta_min) l += t;
        const int64_t j = i + l * d;
        const int delta_node = delta(i, j);
        int64_t s = 0;
        for (int64_t t = (l + 1) / 2;; t = (t + 1) / 2) {
            if (delta(i, i + (s + t) * d) > delta_node) s += t;
            if (t == 1) break;
        }
        const int64_t gamma = i + s * d + std::min(d, 0);
        const uint32_t inner = uint32_t(n_ - 1);
        return {std::min(i, j) == gamma ? inner + uint32_t(gamma) : uint32_t(gamma),
                std::max(i, j) == gamma + 1 ? inner + uint32_t(gamma + 1) : uint32_t(gamma + 1)};
    }

private:
    int delta(int64_t i, int64_t j) const {
        if (j < 0 || j >= n_) return -1;
        const uint64_t x = codes_[size_t(i)] ^ codes_[size_t(j)];
        return x ? std::countl_zero(x) : 64 + std::countl_zero(uint64_t(i ^ j));
    }

    const std::vector<uint64_t>& codes_;
    const int64_t n_;
};

}  // namespace

Bvh build_lbvh(BuildInput&& input, const BuildSettings&) {
    const std::vector<PrimRef>& refs = input.refs;
    const uint32_t n = uint32_t(refs.size());
    if (n == 0) return {};
    Bvh bvh;
    std::vector<uint64_t> codes = morton_codes(refs);
    const std::vector<uint32_t> order = radix_sort(codes);
    bvh.refs.resize(n);
    parallel::for_each(n, kGrain, [&](size_t i) { bvh.refs[i] = refs[order[i]].prim; });
    if (n == 1) {
        bvh.nodes = {{refs[0].bounds(), 0, 1}};
        return bvh;
    }
    // Topology in Karras's numbering: inner nodes 0 .. n - 2 (0 is the root), leaves n - 1 .. 2n - 2.
    const KarrasHierarchy hierarchy(codes);
    std::vector<KarrasHierarchy::Inner> inner(n - 1);
    std::vector<uint32_t> parent(2 * n - 1);
    parallel::for_each(n - 1, kGrain, [&](size_t i) {
        inner[i] = hierarchy.node(int64_t(i));
        parent[inner[i].left] = parent[inner[i].right] = uint32_t(i);
    });
    // Bounds bottom-up: the second child to arrive at a node computes it (Karras 2012, sec. 4).
    std::vector<BBox> bounds(2 * n - 1);
    std::vector<std::atomic<uint8_t>> arrived(n - 1);
    parallel::for_each(n, kGrain, [&](size_t leaf) {
        uint32_t id = n - 1 + uint32_t(leaf);
        bounds[id] = refs[order[leaf]].bounds();
        while (id != 0) {
            id = parent[id];
            if (arrived[id].fetch_add(1, std::memory_order_acq_rel) == 0) return;
            bounds[id] = merge(bounds[inner[id].left], bounds[inner[id].right]);
        }
    });
    // Into canopy's layout: inner node i's two children go to slots 2i + 1 and 2i + 2, so siblings are adjacent
    // and every slot is used; Morton order keeps neighbouring nodes near each other.
    bvh.nodes.resize(2 * size_t(n) - 1);
    bvh.nodes[0] = {bounds[0], 1, 0};
    parallel::for_each(n - 1, kGrain, [&](size_t i) {
        const uint32_t children[2] = {inner[i].left, inner[i].right};
        for (uint32_t c = 0; c < 2; ++c) {
            const uint32_t id = children[c];
            bvh.nodes[2 * i + 1 + c] = id >= n - 1 ? BvhNode{bounds[id], id - (n - 1), 1} : BvhNode{bounds[id], 2 * id + 1, 0};
        }
    });
    return bvh;
}

}  // namespace canopy
