#include "accel/wide_bvh.h"
#include "accel/parallel.h"

#include <array>
#include <bit>
#include <memory>

namespace canopy {
namespace {

// What a wide subtree takes of the output arrays: wide nodes (its root included), leaf entries, and leaves.
struct Extent {
    uint32_t nodes, entries, leaves;
};

// Where a wide subtree's next node slot, leaf entry and leaf go.
using Cursor = Extent;

// A wide node's children as binary nodes (Ganestam and Doggett 2016, sec. 4.2): the binary node's two children,
// then repeatedly the inner child of largest surface area replaced by its two children until there are N.
template <int N>
struct WideChildren {
    std::array<uint32_t, N> node;
    int count = 0;

    WideChildren(const Bvh& bvh, uint32_t index) {
        std::array<float, N> area;  // half area of an inner child; -1 for a leaf, never opened
        auto put = [&](int slot, uint32_t child) {
            node[slot] = child;
            area[slot] = bvh.nodes[child].is_leaf() ? -1.0f : bvh.nodes[child].bounds.half_area();
        };
        put(count++, bvh.nodes[index].index);
        put(count++, bvh.nodes[index].index + 1);
        while (count < N) {
            int widest = -1;
            float widest_area = -1.0f;
            for (int i = 0; i < count; ++i)
                if (area[i] > widest_area) widest = i, widest_area = area[i];
            if (widest < 0) break;
            const uint32_t first = bvh.nodes[node[widest]].index;
            put(widest, first);
            put(count++, first + 1);
        }
    }
    // A root that is a leaf: one leaf child.
    explicit WideChildren(uint32_t leaf) : count(1) { node[0] = leaf; }
};

// Collapses in two passes so that subtrees fill in parallel yet land exactly where the depth-first serial order
// puts them: a node's inner children get consecutive slots, then each child's subtree follows in turn (siblings
// sit next to each other as the traversal visits them), and leaf entries follow the same order. The first pass
// measures every subtree's extent; the second writes, giving each large subtree its own cursor.
template <int N, class LeafSink>
class Collapser {
public:
    Collapser(const Bvh& bvh, WideNodes<N>& nodes, uint32_t (*entries)(int, uint32_t), LeafSink& sink)
        : bvh_(bvh), nodes_(nodes), entries_(entries), sink_(sink),
          extents_(std::make_unique_for_overwrite<Extent[]>(bvh.nodes.size())) {}

    // Returns the extent of the whole tree, once the sink has been told where it goes (`reserve(extent)`).
    Extent run() {
        const bool lone_leaf = bvh_.nodes[0].is_leaf();
        const Extent total = lone_leaf ? Extent{1, entries_(N, bvh_.nodes[0].count), 1} : measure(0, 0);
        nodes_.clear();
        nodes_.resize(total.nodes);
        sink_.reserve(total);
        Cursor at{1, 0, 0};
        if (lone_leaf)
            write_node(WideChildren<N>(0), 0, at);
        else if (total.nodes >= kGrain)
            fill_parallel(0, 0, at);
        else
            fill_serial(0, 0, at);
        return total;
    }

private:
    // Wide subtrees below this many nodes are filled by one task.
    static constexpr uint32_t kGrain = 256;
    // Wide levels whose children are measured concurrently: about 2^9 tasks at any width.
    static constexpr uint32_t kMeasureDepth = 9 / std::bit_width(unsigned(N - 1));

    // The extent of the wide subtree rooted at inner binary node `index`; keeps its inner children's extents
    // where it is large enough for fill_parallel to need them.
    Extent measure(uint32_t index, uint32_t depth) {
        const WideChildren<N> children(bvh_, index);
        std::array<Extent, N> extent;
        auto measure_child = [&](size_t i) {
            const BvhNode& c = bvh_.nodes[children.node[i]];
            extent[i] = c.is_leaf() ? Extent{0, entries_(N, c.count), 1} : measure(children.node[i], depth + 1);
        };
        if (depth < kMeasureDepth)
            parallel::for_each(size_t(children.count), 1, measure_child);
        else
            for (int i = 0; i < children.count; ++i) measure_child(size_t(i));
        Extent total{1, 0, 0};
        for (int i = 0; i < children.count; ++i) total = sum(total, extent[i]);
        if (total.nodes >= kGrain)
            for (int i = 0; i < children.count; ++i) extents_[children.node[i]] = extent[i];
        return total;
    }

    // Writes the large wide subtree rooted at binary node `index` into slot `self`, its descendants from `at`:
    // each inner child's subtree starts where its earlier siblings' extents end, so they fill concurrently.
    void fill_parallel(uint32_t index, uint32_t self, Cursor at) {
        const WideChildren<N> children(bvh_, index);
        write_node(children, self, at);
        std::array<Cursor, N> start;
        for (int i = 0; i < children.count; ++i) {
            if (nodes_[self].is_leaf(i)) continue;
            start[i] = at;
            const Extent& e = extents_[children.node[i]];
            at = sum(at, Extent{e.nodes - 1, e.entries, e.leaves});  // its root took a slot in write_node
        }
        parallel::for_each(size_t(children.count), 1, [&](size_t i) {
            if (nodes_[self].is_leaf(int(i))) return;
            const uint32_t child = children.node[i], slot = nodes_[self].child[i];
            Cursor cursor = start[i];
            if (extents_[child].nodes >= kGrain)
                fill_parallel(child, slot, cursor);
            else
                fill_serial(child, slot, cursor);
        });
    }

    // Writes a small subtree in depth-first order, advancing `at`.
    void fill_serial(uint32_t index, uint32_t self, Cursor& at) {
        const WideChildren<N> children(bvh_, index);
        write_node(children, self, at);
        for (int i = 0; i < children.count; ++i)
            if (!nodes_[self].is_leaf(i)) fill_serial(children.node[i], nodes_[self].child[i], at);
    }

    // Writes node `self`: inner children take the next node slots, leaf children the next entries.
    void write_node(const WideChildren<N>& children, uint32_t self, Cursor& at) {
        WideNode<N>& node = nodes_[self];
        for (int i = 0; i < N; ++i) {
            if (i >= children.count) {
                set_box(node, i, BBox{});  // lower = +inf, upper = -inf: never hit
                node.child[i] = WideNode<N>::kEmpty;
                node.count[i] = 0;
                continue;
            }
            const BvhNode& c = bvh_.nodes[children.node[i]];
            set_box(node, i, c.bounds);
            if (c.is_leaf()) {
                node.child[i] = at.entries;
                node.count[i] = c.count;
                sink_(at.leaves, LeafRun{at.entries, c.index, c.count});
                at.entries += entries_(N, c.count);
                ++at.leaves;
            } else {
                node.child[i] = at.nodes++;
                node.count[i] = 0;
            }
        }
    }

    static void set_box(WideNode<N>& node, int i, const BBox& box) {
        for (int a = 0; a < 3; ++a) {
            node.lower(a, i) = box.lower[a];
            node.upper(a, i) = box.upper[a];
        }
    }

    static Extent sum(const Extent& a, const Extent& b) {
        return {a.nodes + b.nodes, a.entries + b.entries, a.leaves + b.leaves};
    }

    const Bvh& bvh_;
    WideNodes<N>& nodes_;
    uint32_t (*entries_)(int, uint32_t);
    LeafSink& sink_;
    std::unique_ptr<Extent[]> extents_;  // by binary node; written only for children of large subtrees
};

// Keeps the leaves in emission order, for a caller whose leaves hold something else than triangles.
struct RunList {
    std::vector<LeafRun> runs;
    void reserve(const Extent& total) { runs.resize(total.leaves); }
    void operator()(uint32_t leaf, const LeafRun& run) { runs[leaf] = run; }
};

void fill_leaf(LeafTriangle* out, const Bvh& bvh, std::span<const Triangle> triangles, uint32_t first_ref,
               uint32_t count) {
    for (uint32_t i = 0; i < count; ++i) {
        const uint32_t prim = bvh.refs[first_ref + i];
        const Triangle& t = triangles[prim];
        out[i] = {t.v0, prim, t.v1, t.v2};
    }
}

template <int W>
void fill_leaf(TriangleBlock<W>* out, const Bvh& bvh, std::span<const Triangle> triangles, uint32_t first_ref,
               uint32_t count) {
    for (uint32_t b = 0; b < leaf_entries(W, count); ++b) {
        TriangleBlock<W>& block = out[b];
        for (int lane = 0; lane < W; ++lane) {
            const uint32_t i = b * W + uint32_t(lane);
            const uint32_t prim = i < count ? bvh.refs[first_ref + i] : TriangleBlock<W>::kNone;
            const Triangle t = i < count ? triangles[prim] : Triangle{Vec3(0), Vec3(0), Vec3(0)};
            const Vec3* vertices[3] = {&t.v0, &t.v1, &t.v2};
            for (int v = 0; v < 3; ++v)
                for (int a = 0; a < 3; ++a) block.v[v][a][lane] = (*vertices[v])[a];
            block.prim[lane] = prim;
        }
    }
}

// Copies each leaf's triangles into the wide tree as soon as its entries are known.
template <int N>
struct TriangleLeaves {
    WideBvh<N>& out;
    const Bvh& bvh;
    std::span<const Triangle> triangles;
    void reserve(const Extent& total) { out.leaves.resize(total.entries); }
    void operator()(uint32_t, const LeafRun& run) {
        fill_leaf(&out.leaves[run.first_entry], bvh, triangles, run.first_ref, run.count);
    }
};

}  // namespace

template <int N>
std::vector<LeafRun> collapse_nodes(const Bvh& bvh, WideNodes<N>& nodes, uint32_t (*entries)(int, uint32_t),
                                    uint32_t& total_entries) {
    RunList list;
    total_entries = Collapser<N, RunList>(bvh, nodes, entries, list).run().entries;
    return std::move(list.runs);
}

template <int N>
WideBvh<N> collapse(const Bvh& bvh, std::span<const Triangle> triangles) {
    WideBvh<N> out;
    if (bvh.nodes.empty()) return out;
    out.bounds = bvh.nodes[0].bounds;
    TriangleLeaves<N> leaves{out, bvh, triangles};
    Collapser<N, TriangleLeaves<N>>(bvh, out.nodes, &leaf_entries, leaves).run();
    return out;
}

template std::vector<LeafRun> collapse_nodes<2>(const Bvh&, WideNodes<2>&, uint32_t (*)(int, uint32_t), uint32_t&);
template std::vector<LeafRun> collapse_nodes<4>(const Bvh&, WideNodes<4>&, uint32_t (*)(int, uint32_t), uint32_t&);
template std::vector<LeafRun> collapse_nodes<8>(const Bvh&, WideNodes<8>&, uint32_t (*)(int, uint32_t), uint32_t&);
template WideBvh<2> collapse<2>(const Bvh&, std::span<const Triangle>);
template WideBvh<4> collapse<4>(const Bvh&, std::span<const Triangle>);
template WideBvh<8> collapse<8>(const Bvh&, std::span<const Triangle>);

}  // namespace canopy
