// The collapse into the kernels' wide layout: the parallel collapse writes exactly what the depth-first
// order of wide_bvh.h specifies, with any number of threads.
#include "oracle.h"

#include <tbb/global_control.h>

#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

// The collapse written plainly and serially from its specification: a wide node's children are the binary
// node's children, the inner one of largest area opened until there are N (ties to the first); its inner
// children take consecutive slots, then each one's subtree follows in turn; leaves take entries in the order
// their parents are written.
template <int N>
struct SerialCollapse {
    const Bvh& bvh;
    WideNodes<N> nodes;
    std::vector<LeafRun> runs;
    uint32_t entries = 0;

    SerialCollapse(const Bvh& tree) : bvh(tree) {
        nodes.resize(1);
        write(0, tree.nodes[0].is_leaf() ? std::vector<uint32_t>{0} : open(0));
    }

    std::vector<uint32_t> open(uint32_t index) const {
        std::vector<uint32_t> children{bvh.nodes[index].index, bvh.nodes[index].index + 1};
        while (children.size() < size_t(N)) {
            size_t widest = children.size();
            for (size_t i = 0; i < children.size(); ++i) {
                const BvhNode& c = bvh.nodes[children[i]];
                if (c.is_leaf()) continue;
                if (widest == children.size() || c.bounds.half_area() > bvh.nodes[children[widest]].bounds.half_area())
                    widest = i;
            }
            if (widest == children.size()) break;
            const uint32_t opened = children[widest];
            children[widest] = bvh.nodes[opened].index;
            children.push_back(bvh.nodes[opened].index + 1);
        }
        return children;
    }

    void write(uint32_t self, const std::vector<uint32_t>& children) {
        WideNode<N> node;
        for (int i = 0; i < N; ++i) {
            const BBox box = i < int(children.size()) ? bvh.nodes[children[i]].bounds : BBox{};
            for (int a = 0; a < 3; ++a) node.lower(a, i) = box.lower[a], node.upper(a, i) = box.upper[a];
            node.child[i] = WideNode<N>::kEmpty;
            node.count[i] = 0;
        }
        std::vector<uint32_t> inner, slots;
        for (size_t i = 0; i < children.size(); ++i) {
            const BvhNode& c = bvh.nodes[children[i]];
            if (c.is_leaf()) {
                node.child[i] = entries;
                node.count[i] = c.count;
                runs.push_back({entries, c.index, c.count});
                entries += leaf_entries(N, c.count);
            } else {
                node.child[i] = uint32_t(nodes.size() + inner.size());
                inner.push_back(children[i]);
                slots.push_back(node.child[i]);
            }
        }
        nodes.resize(nodes.size() + inner.size());
        nodes[self] = node;
        for (size_t k = 0; k < inner.size(); ++k) write(slots[k], open(inner[k]));
    }
};

template <class T, class A>
bool same_bytes(const std::vector<T, A>& a, const std::vector<T, A>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

bool same_runs(const std::vector<LeafRun>& a, const std::vector<LeafRun>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(LeafRun)) == 0;
}

// Every leaf entry holds its binary leaf's triangles in order, padding lanes no prim at the origin.
constexpr uint32_t kNoPrim = 0xffffffffu;

template <int N>
size_t misplaced_triangles(const WideBvh<N>& wide, const std::vector<LeafRun>& runs, const Bvh& bvh,
                           std::span<const Triangle> tris) {
    size_t wrong = 0;
    for (const LeafRun& run : runs) {
        for (uint32_t i = 0; i < leaf_entries(N, run.count) * uint32_t(block_lanes(N)); ++i) {
            const uint32_t prim = i < run.count ? bvh.refs[run.first_ref + i] : kNoPrim;
            const Triangle t = i < run.count ? tris[prim] : Triangle{Vec3(0), Vec3(0), Vec3(0)};
            if constexpr (N == 2) {
                const LeafTriangle& l = wide.leaves[run.first_entry + i];
                wrong += l.prim != prim || l.v0 != t.v0 || l.v1 != t.v1 || l.v2 != t.v2;
            } else {
                const auto& block = wide.leaves[run.first_entry + i / N];
                const uint32_t lane = i % N;
                const Vec3 v[3] = {t.v0, t.v1, t.v2};
                wrong += block.prim[lane] != prim;
                for (int k = 0; k < 3; ++k)
                    for (int a = 0; a < 3; ++a) wrong += block.v[k][a][lane] != v[k][a];
            }
        }
    }
    return wrong;
}

template <int N>
void check_against_serial(const Bvh& bvh, std::span<const Triangle> tris, const std::string& what) {
    INFO(what << " bvh" << N);
    const SerialCollapse<N> expected(bvh);
    WideNodes<N> nodes;
    uint32_t entries = 0;
    const std::vector<LeafRun> runs = collapse_nodes<N>(bvh, nodes, &leaf_entries, entries);
    CHECK(same_bytes(nodes, expected.nodes));
    CHECK(same_runs(runs, expected.runs));
    CHECK(entries == expected.entries);
    const WideBvh<N> wide = collapse<N>(bvh, tris);
    CHECK(same_bytes(wide.nodes, expected.nodes));
    CHECK(wide.leaves.size() == expected.entries);
    CHECK(misplaced_triangles(wide, expected.runs, bvh, tris) == 0);
}

template <int N>
WideBvh<N> collapse_with_threads(const Bvh& bvh, std::span<const Triangle> tris, int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    return collapse<N>(bvh, tris);
}

template <int N>
void check_thread_independence(const Bvh& bvh, std::span<const Triangle> tris, const std::string& what) {
    INFO(what << " bvh" << N);
    const WideBvh<N> one = collapse_with_threads<N>(bvh, tris, 1), two = collapse_with_threads<N>(bvh, tris, 2);
    CHECK(same_bytes(one.nodes, two.nodes));
    CHECK(same_bytes(one.leaves, two.leaves));
}

}  // namespace

TEST_CASE("the collapse writes the depth-first layout, the same with 1 and 2 threads", "[builders][collapse]") {
    // Large enough that the parallel path splits subtrees (lbvh gives thousands of wide nodes), plus a tree small
    // enough for the serial path alone.
    for (const char* spec : {"gen:cylinders?tris=30000&seed=5", "gen:box?tris=300&seed=6"}) {
        const FlatScene flat = flatten(load_scene(spec));
        for (const char* builder : {"binned", "lbvh", "lbvh-sah", "sbvh"}) {
            const Bvh bvh = find_builder(builder).build(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, BuildSettings{});
            const std::string what = std::string(spec) + " / " + builder;
            check_against_serial<2>(bvh, flat.triangles, what);
            check_against_serial<4>(bvh, flat.triangles, what);
            check_against_serial<8>(bvh, flat.triangles, what);
            check_thread_independence<2>(bvh, flat.triangles, what);
            check_thread_independence<8>(bvh, flat.triangles, what);
        }
    }
}

TEST_CASE("a root that is a leaf collapses to one node with one leaf child", "[builders][collapse]") {
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {Vec3(0, 0, 1), Vec3(1, 0, 1), Vec3(0, 1, 1)}};
    Bvh bvh;
    bvh.nodes = {{merge(BBox::of(tris[0]), BBox::of(tris[1])), 0, 2}};
    bvh.refs = {1, 0};
    check_against_serial<2>(bvh, tris, "leaf root");
    check_against_serial<8>(bvh, tris, "leaf root");
    const WideBvh<8> wide = collapse<8>(bvh, tris);
    REQUIRE(wide.nodes.size() == 1);
    CHECK(wide.nodes[0].count[0] == 2);
    CHECK(wide.nodes[0].is_empty(1));
}
