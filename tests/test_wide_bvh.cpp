// The collapse into the kernels' wide layout: the parallel collapse writes exactly what the depth-first
// order of wide_bvh.h specifies, with any number of threads.
#include "oracle.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <map>
#include <optional>

using namespace canopy;
using namespace canopy::test;

namespace {

constexpr uint32_t kNoPrim = 0xffffffffu;

// CollapseMethod::Optimal's dynamic program written plainly from its equations (wide_bvh.cpp), costs memoised by
// (node, slots), with the same tie rules: the smallest left share among equal costs, fewer slots where they cost no
// more, and a wide node rather than one leaf where the two cost the same.
template <int N>
struct PlainPlan {
    static constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    const Bvh& bvh;
    bool may_merge;
    std::map<std::pair<uint32_t, int>, float> memo;

    uint32_t triangles(uint32_t n) const {
        const BvhNode& node = bvh.nodes[n];
        return node.is_leaf() ? node.count : triangles(node.index) + triangles(node.index + 1);
    }
    float area(uint32_t n) const { return bvh.nodes[n].bounds.half_area(); }
    bool fits_block(uint32_t n) const { return may_merge && triangles(n) <= kLanes; }

    // S(n, k) and the left child's share that reaches it.
    std::pair<float, int> shared(uint32_t n, int k) {
        std::pair<float, int> best{std::numeric_limits<float>::infinity(), 0};
        for (int i = 1; i < k; ++i) {
            const float c = cost(bvh.nodes[n].index, i) + cost(bvh.nodes[n].index + 1, k - i);
            if (c < best.first) best = {c, i};
        }
        return best;
    }
    float as_node(uint32_t n) { return area(n) + shared(n, N).first; }
    bool merged(uint32_t n) { return !bvh.nodes[n].is_leaf() && fits_block(n) && area(n) < as_node(n); }

    // C(n, k), block and node tests both of cost 1.
    float cost(uint32_t n, int k) {
        const BvhNode& node = bvh.nodes[n];
        if (node.is_leaf()) return area(n) * float(leaf_entries(N, node.count));
        if (const auto it = memo.find({n, k}); it != memo.end()) return it->second;
        float c;
        if (k == 1) c = std::min(fits_block(n) ? area(n) : std::numeric_limits<float>::infinity(), as_node(n));
        else c = std::min(cost(n, k - 1), shared(n, k).first);
        return memo[{n, k}] = c;
    }

    // Subtree n given k slots: itself, or its children's shares.
    void unfold(uint32_t n, int k, std::vector<uint32_t>& out) {
        if (!bvh.nodes[n].is_leaf()) {
            while (k > 1 && cost(n, k - 1) <= shared(n, k).first) --k;
            if (k > 1) {
                const int i = shared(n, k).second;
                unfold(bvh.nodes[n].index, i, out);
                unfold(bvh.nodes[n].index + 1, k - i, out);
                return;
            }
        }
        out.push_back(n);
    }
    std::vector<uint32_t> children(uint32_t n) {
        std::vector<uint32_t> out;
        const int i = shared(n, N).second;
        unfold(bvh.nodes[n].index, i, out);
        unfold(bvh.nodes[n].index + 1, N - i, out);
        return out;
    }
};

// The collapse written plainly and serially from its specification. A wide node's children are, for the greedy
// method, the binary node's children, the inner one of largest area opened until there are N (ties to the
// first), and for the optimal method (at widths above 2) what PlainPlan unfolds. Its inner children take
// consecutive slots, then each one's subtree follows in turn; leaves take entries in the order their parents are
// written. With `triangles`, leaves are filled with them, and with blocks (N > 2) the one-triangle leaves of a node
// share blocks, a lane each, and an inner child is one leaf of its subtree's triangles in depth-first order where
// the plan merged it, or greedily where its subtree is at most a block's lanes of one-triangle leaves; without,
// each leaf is a run. Planes are written in `frame`.
template <int N>
struct SerialCollapse {
    using Leaf = LeafOf<N>;
    static constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    const Bvh& bvh;
    std::span<const Triangle> triangles;
    WideNodes<N> nodes;
    std::vector<LeafRun> runs;
    std::vector<Leaf> leaves;
    uint32_t entries = 0;
    PlaneFrame frame;

    std::optional<PlainPlan<N>> plan;

    SerialCollapse(const Bvh& tree, const PlaneFrame& planes, std::span<const Triangle> tris = {},
                   CollapseMethod method = CollapseMethod::Greedy)
        : bvh(tree), triangles(tris), frame(planes) {
        if (method == CollapseMethod::Optimal && N > 2) plan.emplace(PlainPlan<N>{tree, blocks(), {}});
        nodes.resize(1);
        write(0, tree.nodes[0].is_leaf() ? std::vector<uint32_t>{0} : open(0));
    }

    std::vector<uint32_t> open(uint32_t index) {
        if (plan) return plan->children(index);
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
            frame.set_box(node, i, box);
            node.child[i] = WideNode<N>::kEmpty;
            node.count[i] = 0;
        }
        std::vector<uint32_t> inner, slots;
        uint32_t shared_block = 0, shared_lanes = kLanes;  // the block one-triangle leaves fill, its used lanes
        for (size_t i = 0; i < children.size(); ++i) {
            const BvhNode& c = bvh.nodes[children[i]];
            node.count[i] = c.count;
            const std::vector<uint32_t> small = blocks() ? small_subtree_refs(children[i]) : std::vector<uint32_t>{};
            if (!small.empty()) {
                node.child[i] = entries;
                node.count[i] = uint32_t(small.size());
                add_blocks(1);
                for (uint32_t k = 0; k < small.size(); ++k) put(node.child[i], k, bvh.refs[small[k]]);
            } else if (!c.is_leaf()) {
                node.child[i] = uint32_t(nodes.size() + inner.size());
                inner.push_back(children[i]);
                slots.push_back(node.child[i]);
            } else if (blocks() && c.count == 1) {
                if (shared_lanes == kLanes) shared_block = entries, shared_lanes = 0, add_blocks(1);
                node.child[i] = shared_block;
                put(shared_block, shared_lanes++, bvh.refs[c.index]);
            } else {
                node.child[i] = entries;
                runs.push_back({entries, c.index, c.count});
                add_blocks(leaf_entries(N, c.count));
                for (uint32_t k = 0; k < c.count; ++k) put(node.child[i] + k / kLanes, k % kLanes, bvh.refs[c.index + k]);
            }
        }
        nodes.resize(nodes.size() + inner.size());
        nodes[self] = node;
        for (size_t k = 0; k < inner.size(); ++k) write(slots[k], open(inner[k]));
    }

    bool blocks() const { return !triangles.empty() && N > 2; }

    // The refs of an inner node's subtree in depth-first order when it is written as one leaf.
    std::vector<uint32_t> small_subtree_refs(uint32_t index) {
        std::vector<uint32_t> refs;
        if (bvh.nodes[index].is_leaf()) return {};
        if (plan) {
            if (plan->merged(index)) all_refs(index, refs);
            return refs;
        }
        if (!one_triangle_leaves(index, refs) || refs.size() > kLanes) return {};
        return refs;
    }
    void all_refs(uint32_t index, std::vector<uint32_t>& refs) const {
        const BvhNode& n = bvh.nodes[index];
        if (!n.is_leaf()) return all_refs(n.index, refs), all_refs(n.index + 1, refs);
        for (uint32_t k = 0; k < n.count; ++k) refs.push_back(n.index + k);
    }
    bool one_triangle_leaves(uint32_t index, std::vector<uint32_t>& refs) const {
        const BvhNode& n = bvh.nodes[index];
        if (n.is_leaf()) {
            refs.push_back(n.index);
            return n.count == 1;
        }
        return one_triangle_leaves(n.index, refs) && one_triangle_leaves(n.index + 1, refs);
    }

    // Appends leaf entries, every lane empty: prim none, a degenerate triangle at the origin.
    void add_blocks(uint32_t count) {
        entries += count;
        if (triangles.empty()) return;
        Leaf empty;
        std::memset(static_cast<void*>(&empty), 0, sizeof(empty));
        if constexpr (N > 2) std::fill(std::begin(empty.prim), std::end(empty.prim), kNoPrim);
        leaves.resize(entries, empty);
    }

    void put(uint32_t entry, uint32_t lane, uint32_t prim) {
        if (triangles.empty()) return;
        const Triangle& t = triangles[prim];
        if constexpr (N == 2) {
            leaves[entry] = {t.v0, prim, t.v1, t.v2};
        } else {
            const Vec3 v[3] = {t.v0, t.v1, t.v2};
            for (int k = 0; k < 3; ++k)
                for (int a = 0; a < 3; ++a) leaves[entry].v[k][a][lane] = v[k][a];
            leaves[entry].prim[lane] = prim;
        }
    }
};

template <class T, class A, class B>
bool same_bytes(const std::vector<T, A>& a, const std::vector<T, B>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

constexpr CollapseMethod kMethods[] = {CollapseMethod::Optimal, CollapseMethod::Greedy};

const char* name_of(CollapseMethod method) { return method == CollapseMethod::Optimal ? "optimal" : "greedy"; }

template <int N>
void check_against_serial(const Bvh& bvh, std::span<const Triangle> tris, const std::string& what) {
    INFO(what << " bvh" << N);
    const PlaneFrame centred = PlaneFrame::centred(bvh.nodes[0].bounds);
    for (const CollapseMethod method : kMethods) {
        INFO(name_of(method));
        const SerialCollapse<N> runs_only(bvh, centred, {}, method);  // the node half: no triangles, no merges
        WideNodes<N> nodes;
        uint32_t entries = 0;
        const std::vector<LeafRun> runs = collapse_nodes<N>(bvh, nodes, centred, &leaf_entries, entries, method);
        CHECK(same_bytes(nodes, runs_only.nodes));
        CHECK(same_bytes(runs, runs_only.runs));
        CHECK(entries == runs_only.entries);

        const SerialCollapse<N> expected(bvh, centred, tris, method);
        const WideBvh<N> wide = collapse<N>(bvh, tris, method);
        CHECK(wide.frame.origin == centred.origin);
        CHECK(wide.frame.bound == centred.bound);
        CHECK(same_bytes(wide.nodes, expected.nodes));
        CHECK(same_bytes(wide.leaves, expected.leaves));
    }
}

template <int N>
WideBvh<N> collapse_with_threads(const Bvh& bvh, std::span<const Triangle> tris, int threads, CollapseMethod method) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    return collapse<N>(bvh, tris, method);
}

template <int N>
void check_thread_independence(const Bvh& bvh, std::span<const Triangle> tris, const std::string& what) {
    for (const CollapseMethod method : kMethods) {
        INFO(what << " bvh" << N << " " << name_of(method));
        const WideBvh<N> one = collapse_with_threads<N>(bvh, tris, 1, method), two = collapse_with_threads<N>(bvh, tris, 2, method);
        CHECK(same_bytes(one.nodes, two.nodes));
        CHECK(same_bytes(one.leaves, two.leaves));
    }
}

// The cost the optimal method minimises (wide_bvh.cpp): surface area times one per node test (the root's and each
// inner child's) and one per leaf block a leaf child's visit tests.
template <int N>
double modelled_cost(const WideBvh<N>& wide) {
    double cost = wide.bounds.half_area();
    for (const WideNode<N>& node : wide.nodes)
        for (int i = 0; i < N; ++i) {
            if (node.is_empty(i)) continue;
            const BBox box = wide.frame.box(node, i);
            cost += double(box.half_area()) * (node.is_leaf(i) ? double(leaf_entries(N, node.count[i])) : 1.0);
        }
    return cost;
}

}  // namespace

TEST_CASE("the collapse writes the depth-first layout, the same with 1 and 2 threads", "[builders][collapse]") {
    // Large enough that the parallel path splits subtrees (lbvh gives thousands of wide nodes), plus a tree small
    // enough for the serial path alone.
    for (const char* spec : {"gen:cylinders?tris=30000&seed=5", "gen:box?tris=300&seed=6"}) {
        const FlatScene flat = flatten(load_scene(spec));
        // lbvh's trees carry their subtrees' ref ranges, which the collapse reads instead of walking; lbvh-sah,
        // treelet and streelet rewrite an lbvh tree, and must not pass stale ranges on.
        for (const char* builder : {"binned", "lbvh", "lbvh-sah", "sbvh", "treelet", "streelet"}) {
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

TEST_CASE("one-triangle leaves of a wide node share a block, a lane each in child order", "[builders][collapse]") {
    // Greedy collapse, whose choice of children this case spells out; the optimal one shares blocks the same way.
    // Root over inner nodes 1 (the larger, opened first) and 2; node 1 over leaf 3 (triangle 0) and leaf 4
    // (triangles 1 and 2), node 2 over leaves 5 (triangle 3) and 6 (triangle 4). Width 4 opens both: children
    // 3, 5, 4, 6.
    std::vector<Triangle> tris;
    for (int i = 0; i < 5; ++i) tris.push_back({Vec3(float(i), 0, 0), Vec3(float(i) + 0.5f, 0, 0), Vec3(float(i), 0.5f, 0)});
    auto box = [&](std::initializer_list<int> ids) {
        BBox b;
        for (int i : ids) b.extend(BBox::of(tris[size_t(i)]));
        return b;
    };
    Bvh bvh;
    bvh.refs = {0, 1, 2, 3, 4};
    bvh.nodes = {{box({0, 1, 2, 3, 4}), 1, 0}, {box({0, 1, 2}), 3, 0}, {box({3, 4}), 5, 0},
                 {box({0}), 0, 1}, {box({1, 2}), 1, 2}, {box({3}), 3, 1}, {box({4}), 4, 1}};
    check_against_serial<4>(bvh, tris, "shared block");
    check_against_serial<8>(bvh, tris, "shared block");

    const WideBvh<4> wide = collapse<4>(bvh, tris, CollapseMethod::Greedy);
    REQUIRE(wide.nodes.size() == 1);
    REQUIRE(wide.leaves.size() == 2);
    const WideNode<4>& root = wide.nodes[0];
    CHECK(std::vector<uint32_t>(root.child, root.child + 4) == std::vector<uint32_t>{0, 0, 1, 0});
    CHECK(std::vector<uint32_t>(root.count, root.count + 4) == std::vector<uint32_t>{1, 1, 2, 1});
    constexpr int kLanes = block_lanes(4);
    auto lanes = [&](std::vector<uint32_t> prims) {  // padded with kNoPrim to the block's lanes
        prims.resize(size_t(kLanes), kNoPrim);
        return prims;
    };
    const LeafOf<4>& shared = wide.leaves[0];
    CHECK(std::vector<uint32_t>(shared.prim, shared.prim + kLanes) == lanes({0, 3, 4}));
    CHECK(std::vector<uint32_t>(wide.leaves[1].prim, wide.leaves[1].prim + kLanes) == lanes({1, 2}));
    // Its own triangle is found through each leaf child, and the traced hit is the same as without sharing.
    Hit hit;
    CHECK(closest_hit(wide, Ray{{4.1f, 0.1f, 1.0f}, {0, 0, -1}}, hit));
    CHECK(hit.prim == 4);
}

TEST_CASE("greedily, an inner child of at most a block's lanes of one-triangle leaves is one leaf", "[builders][collapse]") {
    // Root over nodes 1 and 2; node 1 over 3 and 4, node 2 over 5 and 6, which width 4 opens into its children.
    // Nodes 3, 5 and 6 hold two one-triangle leaves each: each is written as one leaf of two triangles. Node 4
    // holds a two-triangle leaf, so it stays a wide node.
    std::vector<Triangle> tris;
    for (int i = 0; i < 9; ++i) tris.push_back({Vec3(float(i), 0, 0), Vec3(float(i) + 0.5f, 0, 0), Vec3(float(i), 0.5f, 0)});
    auto box = [&](int first, int last) {
        BBox b;
        for (int i = first; i <= last; ++i) b.extend(BBox::of(tris[size_t(i)]));
        return b;
    };
    Bvh bvh;
    bvh.refs = {0, 1, 2, 3, 4, 5, 6, 7, 8};
    bvh.nodes = {{box(0, 8), 1, 0},                        // 0
                 {box(0, 4), 3, 0}, {box(5, 8), 5, 0},     // 1, 2
                 {box(0, 1), 7, 0}, {box(2, 4), 9, 0},     // 3, 4
                 {box(5, 6), 11, 0}, {box(7, 8), 13, 0},   // 5, 6
                 {box(0, 0), 0, 1}, {box(1, 1), 1, 1},     // 7, 8: under 3
                 {box(2, 3), 2, 2}, {box(4, 4), 4, 1},     // 9, 10: under 4
                 {box(5, 5), 5, 1}, {box(6, 6), 6, 1},     // 11, 12: under 5
                 {box(7, 7), 7, 1}, {box(8, 8), 8, 1}};    // 13, 14: under 6
    check_against_serial<4>(bvh, tris, "merged subtrees");
    check_against_serial<8>(bvh, tris, "merged subtrees");

    const WideBvh<4> wide = collapse<4>(bvh, tris, CollapseMethod::Greedy);
    REQUIRE(wide.nodes.size() == 2);
    const WideNode<4>& root = wide.nodes[0];
    std::vector<uint32_t> counts(root.count, root.count + 4);
    std::sort(counts.begin(), counts.end());
    CHECK(counts == std::vector<uint32_t>{0, 2, 2, 2});  // node 4 inner; 3, 5 and 6 merged
    for (int i = 0; i < 4; ++i) {
        if (!root.is_leaf(i)) continue;
        const TriangleBlock<block_lanes(4)>& block = wide.leaves[root.child[i]];
        CHECK(block.prim[1] == block.prim[0] + 1);  // depth-first order
        CHECK(block.prim[2] == kNoPrim);
    }
    // Width 8 opens everything into the root but nine triangles exceed a block: no merge, the root's leaves.
    CHECK(collapse<8>(bvh, tris, CollapseMethod::Greedy).nodes.size() == 1);
}

TEST_CASE("the optimal collapse writes a subtree that fits a block as one leaf where that costs less", "[builders][collapse]") {
    // Root over node 1 and leaf 2 (triangle 6, far off); node 1 over leaves 3 (triangles 0 to 2) and 4 (3 to 5),
    // six triangles stacked 0.01 apart, so both leaves' boxes are nearly node 1's: one block test over node 1's box
    // costs about half of testing both leaves. The greedy collapse opens node 1 into the root's free slots.
    std::vector<Triangle> tris;
    for (int i = 0; i < 6; ++i) {
        const float z = 0.01f * float(i);
        tris.push_back({Vec3(0, 0, z), Vec3(1, 0, z), Vec3(0, 1, z)});
    }
    tris.push_back({Vec3(10, 0, 0), Vec3(11, 0, 0), Vec3(10, 1, 0)});
    auto box = [&](int first, int last) {
        BBox b;
        for (int i = first; i <= last; ++i) b.extend(BBox::of(tris[size_t(i)]));
        return b;
    };
    Bvh bvh;
    bvh.refs = {0, 1, 2, 3, 4, 5, 6};
    bvh.nodes = {{box(0, 6), 1, 0}, {box(0, 5), 3, 0}, {box(6, 6), 6, 1}, {box(0, 2), 0, 3}, {box(3, 5), 3, 3}};
    check_against_serial<4>(bvh, tris, "merged multi-triangle leaves");
    check_against_serial<8>(bvh, tris, "merged multi-triangle leaves");

    const WideBvh<8> optimal = collapse<8>(bvh, tris), greedy = collapse<8>(bvh, tris, CollapseMethod::Greedy);
    REQUIRE(optimal.nodes.size() == 1);
    const WideNode<8>& root = optimal.nodes[0];
    CHECK(std::vector<uint32_t>(root.count, root.count + 3) == std::vector<uint32_t>{6, 1, 0});
    const TriangleBlock<block_lanes(8)>& block = optimal.leaves[root.child[0]];
    for (uint32_t lane = 0; lane < 6; ++lane) CHECK(block.prim[lane] == lane);  // depth-first order
    CHECK(std::vector<uint32_t>(greedy.nodes[0].count, greedy.nodes[0].count + 4) == std::vector<uint32_t>{3, 1, 3, 0});
    CHECK(modelled_cost(optimal) < modelled_cost(greedy));
    // The nearest of the stacked triangles is found through the merged leaf.
    Hit hit;
    CHECK(closest_hit(optimal, Ray{{0.2f, 0.2f, 1.0f}, {0, 0, -1}}, hit));
    CHECK(hit.prim == 5);
}

TEST_CASE("the optimal collapse costs no more than the greedy one", "[builders][collapse]") {
    // The greedy method's trees are among those the dynamic program chooses from, so its modelled cost bounds the
    // optimal one's, on every builder's tree (lbvh: one-triangle leaves; sbvh: split references).
    for (const char* spec : {"gen:cylinders?tris=20000&seed=3", "gen:box?tris=3000&seed=4", "gen:surface?tris=5000&seed=2"}) {
        const FlatScene flat = flatten(load_scene(spec));
        for (const char* builder : {"binned", "lbvh", "sbvh", "ploc"}) {
            BuildSettings settings;
            settings.leaf_block = 4;
            const Bvh bvh = find_builder(builder).build(BuildInput{flat.triangles, make_prim_refs(flat.triangles)}, settings);
            INFO(spec << " / " << builder);
            CHECK(modelled_cost(collapse<4>(bvh, flat.triangles)) <= modelled_cost(collapse<4>(bvh, flat.triangles, CollapseMethod::Greedy)) * (1 + 1e-5));
            CHECK(modelled_cost(collapse<8>(bvh, flat.triangles)) <= modelled_cost(collapse<8>(bvh, flat.triangles, CollapseMethod::Greedy)) * (1 + 1e-5));
        }
    }
}
