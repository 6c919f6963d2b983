#include "accel/builders/lbvh.h"

#include "accel/morton.h"
#include "accel/parallel.h"

#include <atomic>

namespace canopy {
namespace {

constexpr size_t kGrain = 16 * 1024;
// Leaves ahead whose reference and node slots are fetched early: a leaf's reference is a random read, and its
// node store must reach the cache before the atomic exchange that publishes it can complete.
constexpr size_t kPrefetchDistance = 16;

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
// bounds as Apetrei 2014 ("Fast and Simple Agglomerative LBVH Construction") does: each leaf climbs;
// a node over sorted leaves [l, r] is the left child of the split between r and r + 1 or the right child of
// the split between l - 1 and l, whichever neighbour is less dissimilar. The first child to reach a split
// leaves its range end there and stops; the second completes the parent. Inner node k (the split between
// leaves k and k + 1) keeps its children at slots 2k + 1 and 2k + 2, so every slot is used once, siblings are
// adjacent, and Morton order keeps neighbouring nodes near each other; the root goes to slot 0. Leaf i holds ref
// i, so a node over [l, r] holds refs l to r: the tree's one_ref_leaves, which spare the wide collapse its walks.
Bvh build_lbvh(BuildInput&& input, const BuildSettings&) {
    const std::vector<PrimRef>& refs = input.refs;
    const uint32_t n = uint32_t(refs.size());
    if (n == 0) return {};
    Bvh bvh;
    MortonOrder sorted;
    std::vector<std::atomic<uint32_t>> other_end;  // 0 until a child arrives, then its range end + 1
    // The output arrays are allocated (the refs and the climb counters zeroed, on one thread) while the codes sort.
    parallel::fork_join(n, kGrain, [&] { sorted = sort_by_morton_code(refs); }, [&] {
        bvh.refs.resize(n);
        bvh.nodes.resize(2 * size_t(n) - 1);
        bvh.one_ref_leaves.resize(2 * size_t(n) - 1);
        other_end = std::vector<std::atomic<uint32_t>>(n - 1);
    });
    const std::vector<uint64_t>& codes = sorted.codes;
    const std::vector<uint32_t>& order = sorted.order;
    const Dissimilarity dissimilarity(codes);
    parallel::for_each(n, kGrain, [&](size_t leaf) {
        if (leaf + kPrefetchDistance < n) {
            __builtin_prefetch(&refs[order[leaf + kPrefetchDistance]]);
            __builtin_prefetch(&bvh.nodes[2 * (leaf + kPrefetchDistance)], 1);
        }
        const PrimRef& ref = refs[order[leaf]];
        bvh.refs[leaf] = ref.prim;
        BvhNode node{ref.bounds(), uint32_t(leaf), 1};
        for (uint32_t l = uint32_t(leaf), r = uint32_t(leaf); l != 0 || r != n - 1;) {
            const bool left_child = l == 0 || (r != n - 1 && dissimilarity.less(r, l - 1));
            const uint32_t parent = left_child ? r : l - 1;
            bvh.nodes[2 * parent + (left_child ? 1 : 2)] = node;
            bvh.one_ref_leaves[2 * parent + (left_child ? 1 : 2)] = {l, r - l + 1};
            const uint32_t sibling_end = other_end[parent].exchange((left_child ? l : r) + 1, std::memory_order_acq_rel);
            if (sibling_end == 0) return;
            (left_child ? r : l) = sibling_end - 1;
            node = {merge(bvh.nodes[2 * parent + 1].bounds, bvh.nodes[2 * parent + 2].bounds), 2 * parent + 1, 0};
        }
        bvh.nodes[0] = node;
        bvh.one_ref_leaves[0] = {0, n};
    });
    return bvh;
}

}  // namespace canopy
