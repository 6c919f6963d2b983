#include "accel/builders/lbvh_direct.h"

#include "accel/morton.h"
#include "accel/parallel.h"
#include "accel/wide_bvh_writing.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

namespace canopy {
namespace {

using wide_writing::Cursor;
using wide_writing::Extent;

// 2^(2b/3): the relative area of a Morton cell whose codes differ in their lowest b bits (DirectBuilder::weight).
const std::array<float, 65> kCellArea = [] {
    std::array<float, 65> area{};
    for (int bits = 0; bits <= 64; ++bits) area[bits] = std::exp2(float(2 * bits) / 3.0f);
    return area;
}();

// A wide node's children: ranges [first[i], first[i + 1]) of the sorted references, in Morton order.
template <int N>
struct Children {
    std::array<uint32_t, N + 1> first;
    int count = 0;

    uint32_t size(int i) const { return first[i + 1] - first[i]; }
};

// Builds in two passes, as the collapse writes (wide_bvh.cpp): the first finds every wide node's children from the
// codes alone and measures each subtree, keeping the nodes of the subtrees below the top levels in depth-first
// order; the second writes the top levels and replays those subtrees concurrently, each from its own cursor, into
// the slots the serial depth-first order gives them. Boxes come up from the leaves as the second pass returns.
template <int N>
class DirectBuilder {
    static constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    using Leaf = typename WideBvh<N>::Leaf;

public:
    DirectBuilder(const std::vector<PrimRef>& refs, std::span<const Triangle> triangles, const MortonOrder& sorted, WideBvh<N>& out)
        : refs_(refs), triangles_(triangles), codes_(sorted.codes.data()), order_(sorted.order.data()), out_(out),
          top_depth_(refs.size() < kParallelRefs ? 0 : kTopDepth), top_children_(slot_of(top_depth_, 0)),
          top_extents_(slot_of(top_depth_ + 1, 0)), subtrees_(slot_of(top_depth_ + 1, 0) - slot_of(top_depth_, 0)) {}

    void run() {
        const uint32_t n = uint32_t(refs_.size());
        const Extent total = measure(0, n, 0, 0);
        out_.nodes.resize(total.nodes);
        out_.leaves.resize(total.entries);
        fill(0, 0, 0, Cursor{1, 0, 0});
    }

private:
    // Smaller scenes are built on one thread.
    static constexpr size_t kParallelRefs = 16 * 1024;
    static constexpr uint32_t kTopDepth = wide_writing::kTopDepth<N>;
    // References past the leaf being written (the next leaves', in Morton order) whose PrimRefs are fetched ahead,
    // since the leaves gather them at random and the build waited on them (docs/results.md#builds-and-layouts).
    static constexpr uint32_t kPrefetchRefs = 2 * kLanes;

    static constexpr auto slot_of = wide_writing::top_slot<N>;

    bool is_leaf(uint32_t size) const { return size <= kLanes; }

    // Where range [begin, end) of at least two references splits: at the first code with the highest bit that
    // differs between the range's ends (the codes are sorted, so all share the bits above it), or in the middle.
    uint32_t split(uint32_t begin, uint32_t end) const {
        const uint64_t first = codes_[begin], last = codes_[end - 1];
        if (first == last) return begin + (end - begin) / 2;
        const int bit = 63 - std::countl_zero(first ^ last);
        return uint32_t(std::partition_point(codes_ + begin + 1, codes_ + end, [&](uint64_t c) { return !(c >> bit & 1); }) - codes_);
    }

    // A range's weight in the SAH, its references times the area of the Morton cell that holds them (the cell whose
    // code prefix they share: its area quarters with every three bits of prefix, so it grows as 2^(2b/3) with b, the
    // bits below the prefix). Equal codes share one point: the least weight for their count.
    float weight(uint32_t begin, uint32_t end) const {
        const int bits = 64 - std::countl_zero(codes_[begin] ^ codes_[end - 1]);
        return float(end - begin) * kCellArea[bits];
    }

    // The children of the wide node over [begin, end): the whole range, then the child of the largest weight that
    // does not fit a block split in two (the first of equals), until there are N or all fit a block. Splitting by
    // count alone (Embree's Morton builder's rule) traced slower over ten scenes
    // (docs/results.md#lbvhs-direct-wide-tree).
    Children<N> children_of(uint32_t begin, uint32_t end) const {
        Children<N> c;
        std::array<float, N> weights;
        c.first[0] = begin, c.first[1] = end, c.count = 1;
        weights[0] = weight(begin, end);
        while (c.count < N) {
            int heaviest = -1;
            for (int i = 0; i < c.count; ++i)
                if (c.size(i) > kLanes && (heaviest < 0 || weights[i] > weights[heaviest])) heaviest = i;
            if (heaviest < 0) break;
            const uint32_t middle = split(c.first[heaviest], c.first[heaviest + 1]);
            for (int k = c.count; k > heaviest; --k) c.first[k + 1] = c.first[k];
            for (int k = c.count - 1; k > heaviest; --k) weights[k + 1] = weights[k];
            c.first[heaviest + 1] = middle;
            ++c.count;
            weights[heaviest] = weight(c.first[heaviest], middle);
            weights[heaviest + 1] = weight(middle, c.first[heaviest + 2]);
        }
        return c;
    }

    // What a wide node takes itself: its slot, and a block for each leaf child.
    Extent own_extent(const Children<N>& c) const {
        Extent own{1, 0, 0};
        for (int i = 0; i < c.count; ++i)
            if (is_leaf(c.size(i))) ++own.entries, ++own.leaves;
        return own;
    }

    // The extent of the wide subtree over [begin, end), reached from the root by `path`.
    Extent measure(uint32_t begin, uint32_t end, uint32_t depth, uint32_t path) {
        if (depth == top_depth_) return record(begin, end, subtrees_[path]);
        const Children<N> c = children_of(begin, end);
        top_children_[slot_of(depth, path)] = c;
        parallel::for_each(size_t(c.count), 1, [&](size_t i) {
            if (!is_leaf(c.size(int(i))))
                top_extents_[slot_of(depth + 1, path * N + uint32_t(i))] = measure(c.first[i], c.first[i + 1], depth + 1, path * N + uint32_t(i));
        });
        Extent total = own_extent(c);
        for (int i = 0; i < c.count; ++i)
            if (!is_leaf(c.size(i))) total += top_extents_[slot_of(depth + 1, path * N + uint32_t(i))];
        return total;
    }

    // Measures a subtree below the top levels, appending its wide nodes in depth-first order.
    Extent record(uint32_t begin, uint32_t end, std::vector<Children<N>>& out) {
        const Children<N> c = children_of(begin, end);
        out.push_back(c);
        Extent total = own_extent(c);
        for (int i = 0; i < c.count; ++i)
            if (!is_leaf(c.size(i))) total += record(c.first[i], c.first[i + 1], out);
        return total;
    }

    // Gives each leaf child its block and each inner child its node slot, in child order, from `at`.
    std::array<uint32_t, N> place_children(const Children<N>& c, Cursor& at) const {
        std::array<uint32_t, N> slot{};
        for (int i = 0; i < c.count; ++i) {
            if (is_leaf(c.size(i))) {
                slot[i] = at.entries++;
                ++at.leaves;
            } else {
                slot[i] = at.nodes++;
            }
        }
        return slot;
    }

    // Writes the top-level subtree at `path` into slot `self`, its descendants from `at`: each inner
    // child's subtree starts where its earlier siblings' extents end, so they are written concurrently. Returns
    // its box.
    BBox fill(uint32_t self, uint32_t depth, uint32_t path, Cursor at) {
        if (depth == top_depth_) {
            size_t next = 0;
            const BBox box = replay(subtrees_[path], next, self, at);
            wide_writing::stream_fence();
            return box;
        }
        const Children<N>& c = top_children_[slot_of(depth, path)];
        const std::array<uint32_t, N> slot = place_children(c, at);
        std::array<Cursor, N> start;
        for (int i = 0; i < c.count; ++i) {
            if (is_leaf(c.size(i))) continue;
            start[i] = at;
            const Extent& e = top_extents_[slot_of(depth + 1, path * N + uint32_t(i))];
            at += Extent{e.nodes - 1, e.entries, e.leaves};  // its root took a slot in place_children
        }
        std::array<BBox, N> box;
        parallel::for_each(size_t(c.count), 1, [&](size_t i) {
            box[i] = is_leaf(c.size(int(i))) ? write_leaf(c.first[i], c.first[i + 1], slot[i])
                                             : fill(slot[i], depth + 1, path * N + uint32_t(i), start[i]);
            wide_writing::stream_fence();  // on the thread that streamed
        });
        const BBox total = write_node(c, slot, box, self);
        wide_writing::stream_fence();
        return total;
    }

    // Writes the recorded node `next` into slot `self`, then its subtree's nodes, which follow it in depth-first
    // order. Returns its box.
    BBox replay(const std::vector<Children<N>>& recorded, size_t& next, uint32_t self, Cursor& at) {
        const Children<N>& c = recorded[next++];
        const std::array<uint32_t, N> slot = place_children(c, at);
        std::array<BBox, N> box;
        for (int i = 0; i < c.count; ++i)
            box[i] = is_leaf(c.size(i)) ? write_leaf(c.first[i], c.first[i + 1], slot[i]) : replay(recorded, next, slot[i], at);
        return write_node(c, slot, box, self);
    }

    // The block of sorted references [begin, end), a lane each in order; returns their box.
    BBox write_leaf(uint32_t begin, uint32_t end, uint32_t entry) {
        static const Leaf empty = wide_writing::empty_block<kLanes>();
        const uint32_t n = uint32_t(refs_.size());
        for (uint32_t i = end; i < std::min(end + kPrefetchRefs, n); ++i) __builtin_prefetch(&refs_[order_[i]]);
        // The next leaf's triangles, through its refs, which the previous leaf fetched.
        for (uint32_t i = end; i < std::min(end + kLanes, n); ++i) {
            const char* triangle = reinterpret_cast<const char*>(&triangles_[refs_[order_[i]].prim]);
            __builtin_prefetch(triangle);
            __builtin_prefetch(triangle + sizeof(Triangle) - 1);
        }
        Leaf block = empty;
        BBox box;
        for (uint32_t i = begin; i < end; ++i) {
            const PrimRef& ref = refs_[order_[i]];
            box.extend(ref.bounds());
            wide_writing::put_triangle(block, i - begin, ref.prim, triangles_[ref.prim]);
        }
        wide_writing::stream(&out_.leaves[entry], block);
        return box;
    }

    BBox write_node(const Children<N>& c, const std::array<uint32_t, N>& slot, const std::array<BBox, N>& box, uint32_t self) {
        WideNode<N> node;  // assembled aside and streamed, as leaf blocks are
        BBox total;
        for (int i = 0; i < N; ++i) {
            const bool used = i < c.count;
            out_.frame.set_box(node, i, used ? box[i] : BBox{});  // an empty box is inverted: never hit
            node.child[i] = used ? slot[i] : WideNode<N>::kEmpty;
            node.count[i] = used && is_leaf(c.size(i)) ? c.size(i) : 0;
            if (used) total.extend(box[i]);
        }
        wide_writing::stream(&out_.nodes[self], node);
        return total;
    }

    const std::vector<PrimRef>& refs_;
    std::span<const Triangle> triangles_;
    const uint64_t* codes_;
    const uint32_t* order_;
    WideBvh<N>& out_;
    const uint32_t top_depth_;
    std::vector<Children<N>> top_children_;        // by top-level slot (slot_of), levels above top_depth_
    std::vector<Extent> top_extents_;              // by top-level slot
    std::vector<std::vector<Children<N>>> subtrees_;  // by path at top_depth_
};

}  // namespace

template <int N>
WideBvh<N> build_wide_lbvh(BuildInput&& input) {
    static_assert(N > 2, "one block per leaf: widths 4 and 8");
    WideBvh<N> out;
    if (input.refs.empty()) return out;
    const MortonOrder sorted = sort_by_morton_code(input.refs);
    out.bounds = sorted.bounds;
    out.frame = PlaneFrame::centred(out.bounds);
    DirectBuilder<N>(input.refs, input.triangles, sorted, out).run();
    return out;
}

template WideBvh<4> build_wide_lbvh<4>(BuildInput&&);
template WideBvh<8> build_wide_lbvh<8>(BuildInput&&);

}  // namespace canopy
