#include "accel/lbvh.h"

#include "accel/parallel.h"

#include <array>
#include <atomic>
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

// Dissimilarity of sorted neighbours i and i + 1: the XOR of their codes, then (for equal codes, which Karras
// 2012, sec. 4 tells apart by position) the XOR of their positions. Lexicographic order on the pair ranks
// splits as the binary radix tree does, by the highest differing bit of the position-augmented codes.
struct Dissimilarity {
    explicit Dissimilarity(const std::vector<uint64_t>& codes) : codes_(codes) {}
    bool less(uint32_t i, uint32_t j) const {
        const uint64_t a = codes_[i] ^ codes_[i + 1], b = codes_[j] ^ codes_[j + 1];
        return a != b ? a < b : (i ^ (i + 1)) < (j ^ (j + 1));
    }
    const std::vector<uint64_t>& codes_;
};

}  // namespace

// The binary radix tree over the sorted codes (Karras 2012, sec. 3 and 4), built bottom-up in one pass with its
// bounds as Apetrei 2014 ("Fast and Simple Agglomerative LBVH Construction", sec. 3) does: each leaf climbs;
// a node over sorted leaves [l, r] is the left child of the split between r and r + 1 or the right child of
// the split between l - 1 and l, whichever neighbour is less dissimilar. The first child to reach a split
// leaves its range end there and stops; the second completes the parent. Inner node k (the split between
// leaves k and k + 1) keeps its children at slots 2k + 1 and 2k + 2, so every slot is used once, siblings are
// adjacent, and Morton order keeps neighbouring nodes near each other; the root goes to slot 0.
Bvh build_lbvh(BuildInput&& input, const BuildSettings&) {
    const std::vector<PrimRef>& refs = input.refs;
    const uint32_t n = uint32_t(refs.size());
    if (n == 0) return {};
    Bvh bvh;
    std::vector<uint64_t> codes = morton_codes(refs);
    const std::vector<uint32_t> order = radix_sort(codes);
    bvh.refs.resize(n);
    bvh.nodes.resize(2 * size_t(n) - 1);
    const Dissimilarity dissimilarity(codes);
    std::vector<std::atomic<uint32_t>> other_end(n - 1);  // 0 until a child arrives, then its range end + 1
    parallel::for_each(n, kGrain, [&](size_t leaf) {
        const PrimRef& ref = refs[order[leaf]];
        bvh.refs[leaf] = ref.prim;
        BvhNode node{ref.bounds(), uint32_t(leaf), 1};
        for (uint32_t l = uint32_t(leaf), r = uint32_t(leaf); l != 0 || r != n - 1;) {
            const bool left_child = l == 0 || (r != n - 1 && dissimilarity.less(r, l - 1));
            const uint32_t parent = left_child ? r : l - 1;
            bvh.nodes[2 * parent + (left_child ? 1 : 2)] = node;
            const uint32_t sibling_end = other_end[parent].exchange((left_child ? l : r) + 1, std::memory_order_acq_rel);
            if (sibling_end == 0) return;
            (left_child ? r : l) = sibling_end - 1;
            node = {merge(bvh.nodes[2 * parent + 1].bounds, bvh.nodes[2 * parent + 2].bounds), 2 * parent + 1, 0};
        }
        bvh.nodes[0] = node;
    });
    return bvh;
}

}  // namespace canopy
