#include "accel/wide_bvh.h"
#include "accel/parallel.h"

#include <array>

namespace canopy {
namespace {

template <int N>
class Collapser {
public:
    Collapser(const Bvh& bvh, WideNodes<N>& nodes, uint32_t (*entries)(int, uint32_t))
        : bvh_(bvh), nodes_(nodes), entries_(entries) {}

    // Writes every node; returns the leaves in emission order, for filling WideBvh::leaves in parallel.
    std::vector<LeafRun> run() {
        nodes_.resize(1);
        if (bvh_.nodes[0].is_leaf()) {
            const uint32_t lone[1] = {0};
            emit(0, std::span<const uint32_t>(lone, 1));
        } else {
            emit_children_of(0, 0);
        }
        return std::move(leaf_runs_);
    }

    uint32_t leaf_entries() const { return leaf_entries_; }

private:
    // Writes wide node `self`, whose children come from opening binary node `index`.
    void emit_children_of(uint32_t index, uint32_t self) {
        std::array<uint32_t, N> open{};
        int n = 0;
        open[n++] = bvh_.nodes[index].index;
        open[n++] = bvh_.nodes[index].index + 1;
        while (n < N) {
            int widest = -1;
            float widest_area = -1.0f;
            for (int i = 0; i < n; ++i) {
                const BvhNode& c = bvh_.nodes[open[i]];
                if (!c.is_leaf() && c.bounds.half_area() > widest_area) widest = i, widest_area = c.bounds.half_area();
            }
            if (widest < 0) break;
            const uint32_t first = bvh_.nodes[open[widest]].index;
            open[widest] = first;
            open[n++] = first + 1;
        }
        emit(self, std::span<const uint32_t>(open.data(), size_t(n)));
    }

    // Writes the node at `self`: its inner children get consecutive slots first, then each is filled in
    // turn, so siblings sit next to each other in memory as the traversal visits them.
    void emit(uint32_t self, std::span<const uint32_t> children) {
        for (int i = 0; i < N; ++i) set_empty(self, i);
        uint32_t next = uint32_t(nodes_.size());
        for (size_t i = 0; i < children.size(); ++i) {
            const BvhNode& c = bvh_.nodes[children[i]];
            set_box(self, int(i), c.bounds);
            if (c.is_leaf()) {
                nodes_[self].child[i] = leaf_entries_;
                nodes_[self].count[i] = c.count;
                leaf_runs_.push_back({leaf_entries_, c.index, c.count});
                leaf_entries_ += entries_(N, c.count);
            } else {
                nodes_[self].child[i] = next++;
                nodes_[self].count[i] = 0;
            }
        }
        nodes_.resize(next);
        for (size_t i = 0; i < children.size(); ++i)
            if (!bvh_.nodes[children[i]].is_leaf()) emit_children_of(children[i], nodes_[self].child[i]);
    }

    void set_box(uint32_t node, int i, const BBox& box) {
        for (int a = 0; a < 3; ++a) {
            nodes_[node].lower(a, i) = box.lower[a];
            nodes_[node].upper(a, i) = box.upper[a];
        }
    }

    void set_empty(uint32_t node, int i) {
        set_box(node, i, BBox{});  // lower = +inf, upper = -inf
        nodes_[node].child[i] = WideNode<N>::kEmpty;
        nodes_[node].count[i] = 0;
    }

    const Bvh& bvh_;
    WideNodes<N>& nodes_;
    uint32_t (*entries_)(int, uint32_t);
    std::vector<LeafRun> leaf_runs_;
    uint32_t leaf_entries_ = 0;
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

}  // namespace

template <int N>
std::vector<LeafRun> collapse_nodes(const Bvh& bvh, WideNodes<N>& nodes, uint32_t (*entries)(int, uint32_t),
                                    uint32_t& total_entries) {
    nodes.clear();
    nodes.reserve(bvh.nodes.size() / 2 + 1);
    Collapser<N> collapser(bvh, nodes, entries);
    std::vector<LeafRun> runs = collapser.run();
    total_entries = collapser.leaf_entries();
    return runs;
}

template <int N>
WideBvh<N> collapse(const Bvh& bvh, std::span<const Triangle> triangles) {
    WideBvh<N> out;
    if (bvh.nodes.empty()) return out;
    out.bounds = bvh.nodes[0].bounds;
    uint32_t entries = 0;
    const std::vector<LeafRun> runs = collapse_nodes<N>(bvh, out.nodes, &leaf_entries, entries);
    out.leaves.resize(entries);
    parallel::for_each(runs.size(), 4 * 1024, [&](size_t i) {
        fill_leaf(&out.leaves[runs[i].first_entry], bvh, triangles, runs[i].first_ref, runs[i].count);
    });
    return out;
}

template std::vector<LeafRun> collapse_nodes<2>(const Bvh&, WideNodes<2>&, uint32_t (*)(int, uint32_t), uint32_t&);
template std::vector<LeafRun> collapse_nodes<4>(const Bvh&, WideNodes<4>&, uint32_t (*)(int, uint32_t), uint32_t&);
template std::vector<LeafRun> collapse_nodes<8>(const Bvh&, WideNodes<8>&, uint32_t (*)(int, uint32_t), uint32_t&);
template WideBvh<2> collapse<2>(const Bvh&, std::span<const Triangle>);
template WideBvh<4> collapse<4>(const Bvh&, std::span<const Triangle>);
template WideBvh<8> collapse<8>(const Bvh&, std::span<const Triangle>);

}  // namespace canopy
