#include "accel/kdtree.h"

#include "accel/parallel.h"
#include "accel/triangle_clipping.h"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <utility>

namespace canopy {
namespace {

// Nodes with at least this many triangles build their two subtrees as parallel tasks.
constexpr size_t kParallelGrain = 2048;

// Event types in the order the paper sorts them at equal positions: ends, then planars, then starts.
enum EventType : uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };

// A candidate plane of one triangle's clipped bounds. `tri` is the triangle's index in its node.
struct Event {
    float pos;
    uint32_t tri;
    uint32_t key;  // axis << 2 | type: sorting by (key's axis, pos, key's type) is the paper's order per axis

    int axis() const { return int(key >> 2); }
    uint32_t type() const { return key & 3u; }
};

bool operator<(const Event& a, const Event& b) {
    if (a.axis() != b.axis()) return a.axis() < b.axis();
    if (a.pos != b.pos) return a.pos < b.pos;
    return a.type() < b.type();
}

// The events of one box: a planar event on an axis where it is flat, else a start and an end.
void add_events(std::vector<Event>& out, const BBox& box, uint32_t tri) {
    for (uint32_t k = 0; k < 3; ++k) {
        if (box.lower[k] == box.upper[k]) {
            out.push_back({box.lower[k], tri, k << 2 | kPlanar});
        } else {
            out.push_back({box.lower[k], tri, k << 2 | kStart});
            out.push_back({box.upper[k], tri, k << 2 | kEnd});
        }
    }
}

// A node to build: its triangles (scene indices and clipped bounds, by index in the node), their events sorted,
// its voxel, and the references its subtree may hold (its share of the cap).
struct NodeInput {
    std::vector<uint32_t> prims;
    std::vector<BBox> boxes;
    std::vector<Event> events;
    BBox voxel;
    uint64_t budget = 0;
    uint32_t depth = 0;
};

// A built subtree, indices relative to its own arrays: leaves' `first` into refs, inner nodes' above child into nodes.
struct Subtree {
    std::vector<KdNode> nodes;
    std::vector<uint32_t> refs;
    uint32_t depth = 0;
};

struct Split {
    float cost = std::numeric_limits<float>::infinity();
    int axis = -1;
    float pos = 0;
    bool planar_left = false;  // where triangles lying in the plane go
    uint32_t left = 0, right = 0;
};

enum Side : uint8_t { kBoth, kLeftOnly, kRightOnly };

class KdBuilder {
public:
    KdBuilder(std::span<const Triangle> triangles, const KdSettings& settings, uint32_t max_depth)
        : triangles_(triangles), s_(settings), max_depth_(max_depth) {}

    void build(NodeInput&& in, Subtree& out) const {
        const Split split = find_plane(in);
        const auto n = uint32_t(in.prims.size());
        // The paper's termination: a leaf when no split is cheaper than intersecting every triangle, at the depth limit, or when
        // the split's references would exceed this subtree's share of the cap.
        if (split.axis < 0 || split.cost >= s_.intersection * float(n) || in.depth >= max_depth_ ||
            uint64_t(split.left) + split.right > in.budget) {
            return make_leaf(in, out);
        }
        std::pair<NodeInput, NodeInput> children = partition(std::move(in), split);
        NodeInput &left = children.first, &right = children.second;
        const auto self = uint32_t(out.nodes.size());
        KdNode node{uint32_t(split.axis), {}};
        node.split = split.pos;
        out.nodes.push_back(node);
        const size_t work = left.prims.size() + right.prims.size();
        if (work >= kParallelGrain) {  // the above subtree apart, appended after: one copy per parallel level
            Subtree above;
            parallel::fork_join(work, kParallelGrain, [&] { build(std::move(left), out); }, [&] { build(std::move(right), above); });
            out.nodes[self].bits |= uint32_t(out.nodes.size()) << 2;
            append(out, above);
        } else {
            build(std::move(left), out);
            out.nodes[self].bits |= uint32_t(out.nodes.size()) << 2;
            build(std::move(right), out);
        }
    }

private:
    static void make_leaf(const NodeInput& in, Subtree& out) {
        KdNode leaf{uint32_t(in.prims.size()) << 2 | 3u, {}};
        leaf.first = uint32_t(out.refs.size());
        out.nodes.push_back(leaf);
        out.refs.insert(out.refs.end(), in.prims.begin(), in.prims.end());
        out.depth = std::max(out.depth, in.depth);
    }

    // Appends `b` after `a`'s nodes and refs, shifting its indices.
    static void append(Subtree& a, const Subtree& b) {
        const auto node_offset = uint32_t(a.nodes.size()), ref_offset = uint32_t(a.refs.size());
        for (KdNode node : b.nodes) {
            if (node.is_leaf()) node.first += ref_offset;
            else node.bits += node_offset << 2;
            a.nodes.push_back(node);
        }
        a.refs.insert(a.refs.end(), b.refs.begin(), b.refs.end());
        a.depth = std::max(a.depth, b.depth);
    }

    // The paper's cost of a split: lambda(p) (K_T + K_I (P_L N_L + P_R N_R)), P the voxels' area ratios.
    float cost(float p_left, float p_right, uint32_t n_left, uint32_t n_right) const {
        const float c = s_.traversal + s_.intersection * (p_left * float(n_left) + p_right * float(n_right));
        return (n_left == 0 || n_right == 0) ? s_.empty_bonus * c : c;
    }

    // The paper's sweep (one pass per axis over the sorted events): the counts left, in and right
    // of every candidate plane, and the cheaper side for the triangles lying in it (its SAH(p, V, N_L,
    // N_R, N_P)). Planes on the voxel's boundary are skipped: they cut off a flat, empty voxel and gain nothing.
    Split find_plane(const NodeInput& in) const {
        Split best;
        const float area = in.voxel.half_area();
        if (!(area > 0.0f)) return best;
        const auto n = uint32_t(in.prims.size());
        const std::vector<Event>& e = in.events;
        size_t i = 0;
        for (int k = 0; k < 3; ++k) {
            uint32_t n_left = 0, n_right = n;
            while (i < e.size() && e[i].axis() == k) {
                const float p = e[i].pos;
                uint32_t ends = 0, planars = 0, starts = 0;
                for (; i < e.size() && e[i].axis() == k && e[i].pos == p && e[i].type() == kEnd; ++i) ++ends;
                for (; i < e.size() && e[i].axis() == k && e[i].pos == p && e[i].type() == kPlanar; ++i) ++planars;
                for (; i < e.size() && e[i].axis() == k && e[i].pos == p && e[i].type() == kStart; ++i) ++starts;
                n_right -= planars + ends;
                if (p > in.voxel.lower[k] && p < in.voxel.upper[k]) {
                    BBox below = in.voxel, above = in.voxel;
                    below.upper[k] = above.lower[k] = p;
                    const float p_left = below.half_area() / area, p_right = above.half_area() / area;
                    const float with_left = cost(p_left, p_right, n_left + planars, n_right);
                    const float with_right = cost(p_left, p_right, n_left, n_right + planars);
                    const float c = std::min(with_left, with_right);
                    if (c < best.cost) {
                        const bool planar_left = with_left <= with_right;
                        best = {c, k, p, planar_left, n_left + (planar_left ? planars : 0),
                                n_right + (planar_left ? 0 : planars)};
                    }
                }
                n_left += starts + planars;
            }
        }
        return best;
    }

    // The paper's classification and splicing: triangles on one side keep their events, in order; straddling ones
    // are clipped exactly to each child's voxel, and their new events sorted and merged in. Linear but for the
    // sort of the straddlers' events.
    std::pair<NodeInput, NodeInput> partition(NodeInput&& in, const Split& split) const {
        const size_t n = in.prims.size();
        const uint64_t budget = in.budget;
        std::vector<Side> side(n, kBoth);
        for (const Event& ev : in.events) {
            if (ev.axis() != split.axis) continue;
            if (ev.type() == kEnd && ev.pos <= split.pos) side[ev.tri] = kLeftOnly;
            else if (ev.type() == kStart && ev.pos >= split.pos) side[ev.tri] = kRightOnly;
            else if (ev.type() == kPlanar) {
                const bool left = ev.pos < split.pos || (ev.pos == split.pos && split.planar_left);
                side[ev.tri] = left ? kLeftOnly : kRightOnly;
            }
        }
        NodeInput left, right;
        left.voxel = right.voxel = in.voxel;
        left.voxel.upper[split.axis] = right.voxel.lower[split.axis] = split.pos;
        left.depth = right.depth = in.depth + 1;
        std::vector<uint32_t> left_index(n), right_index(n);
        std::vector<Event> clipped_left, clipped_right;
        for (size_t t = 0; t < n; ++t) {
            BBox lb, rb;
            if (side[t] == kBoth) {
                std::tie(lb, rb) = split_triangle_bounds(triangles_[in.prims[t]], in.boxes[t], split.axis, split.pos);
            } else {
                (side[t] == kLeftOnly ? lb : rb) = in.boxes[t];
            }
            if (!lb.empty()) {
                left_index[t] = uint32_t(left.prims.size());
                if (side[t] == kBoth) add_events(clipped_left, lb, left_index[t]);
                left.prims.push_back(in.prims[t]);
                left.boxes.push_back(lb);
            }
            if (!rb.empty()) {
                right_index[t] = uint32_t(right.prims.size());
                if (side[t] == kBoth) add_events(clipped_right, rb, right_index[t]);
                right.prims.push_back(in.prims[t]);
                right.boxes.push_back(rb);
            }
        }
        std::sort(clipped_left.begin(), clipped_left.end());
        std::sort(clipped_right.begin(), clipped_right.end());
        std::vector<Event> kept_left, kept_right;
        kept_left.reserve(in.events.size());
        kept_right.reserve(in.events.size());
        for (const Event& ev : in.events) {
            if (side[ev.tri] == kLeftOnly) kept_left.push_back({ev.pos, left_index[ev.tri], ev.key});
            else if (side[ev.tri] == kRightOnly) kept_right.push_back({ev.pos, right_index[ev.tri], ev.key});
        }
        in = NodeInput{};  // the parent's arrays are freed before the children's grow
        left.events.resize(kept_left.size() + clipped_left.size());
        std::merge(kept_left.begin(), kept_left.end(), clipped_left.begin(), clipped_left.end(), left.events.begin());
        right.events.resize(kept_right.size() + clipped_right.size());
        std::merge(kept_right.begin(), kept_right.end(), clipped_right.begin(), clipped_right.end(), right.events.begin());
        // Shares of the cap in proportion to the references: each child's covers its own, as the parent's
        // covered both (budget >= left + right was checked), so leaves never exceed the root's budget.
        const uint64_t total = left.prims.size() + right.prims.size();
        left.budget = uint64_t((unsigned __int128)budget * left.prims.size() / total);
        right.budget = budget - left.budget;
        return {std::move(left), std::move(right)};
    }

    std::span<const Triangle> triangles_;
    KdSettings s_;
    uint32_t max_depth_;
};

// A leaf's references in the builder's array and its blocks in the tree's.
struct LeafCopy {
    uint32_t first_ref, first_block, count;
};

// Lane `lane` of `block`: triangle `prim` of the scene, or padding (TriangleBlock's degenerate triangle at the
// origin, prim kNone) for kNone.
void put_lane(KdBlock& block, uint32_t lane, uint32_t prim, std::span<const Triangle> triangles) {
    const Triangle t = prim == KdBlock::kNone ? Triangle{Vec3(0.0f), Vec3(0.0f), Vec3(0.0f)} : triangles[prim];
    const Vec3* vertices[3] = {&t.v0, &t.v1, &t.v2};
    for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) block.v[v][a][lane] = (*vertices[v])[a];
    block.prim[lane] = prim;
}

// Re-points every leaf from its first reference to its first block and returns the blocks, leaves in node order.
std::vector<KdBlock> leaf_blocks(std::vector<KdNode>& nodes, std::span<const uint32_t> refs, std::span<const Triangle> triangles) {
    std::vector<LeafCopy> leaves;
    uint32_t blocks = 0;
    for (KdNode& node : nodes) {
        if (!node.is_leaf()) continue;
        leaves.push_back({node.first, blocks, node.count()});
        node.first = blocks;
        blocks += kd_blocks(node.count());
    }
    std::vector<KdBlock> out(blocks);
    parallel::for_each(leaves.size(), 1024, [&](size_t i) {
        const LeafCopy& leaf = leaves[i];
        for (uint32_t lane = 0; lane < kd_blocks(leaf.count) * kKdLanes; ++lane) {
            const uint32_t prim = lane < leaf.count ? refs[leaf.first_ref + lane] : KdBlock::kNone;
            put_lane(out[leaf.first_block + lane / kKdLanes], lane % kKdLanes, prim, triangles);
        }
    });
    return out;
}

}  // namespace

KdTree build_kdtree(std::span<const Triangle> triangles, const KdSettings& settings) {
    if (!(settings.traversal >= 0.0f && settings.intersection > 0.0f && settings.empty_bonus > 0.0f &&
          settings.empty_bonus <= 1.0f && settings.max_references_per_triangle >= 1.0))
        throw std::invalid_argument("kd-tree settings: costs must be positive, the empty bonus in (0, 1] and the "
                                    "reference cap at least 1 per triangle");
    const size_t n = triangles.size();
    NodeInput root;
    root.prims.resize(n);
    root.boxes.resize(n);
    parallel::for_each(n, 4096, [&](size_t t) {
        root.prims[t] = uint32_t(t);
        root.boxes[t] = BBox::of(triangles[t]);
    });
    root.voxel = parallel::reduce(
        n, 4096, BBox{},
        [&](size_t b, size_t e) {
            BBox box;
            for (size_t t = b; t < e; ++t) box.extend(root.boxes[t]);
            return box;
        },
        [](BBox a, const BBox& b) { return merge(a, b); });
    root.events.reserve(6 * n);
    for (size_t t = 0; t < n; ++t) add_events(root.events, root.boxes[t], uint32_t(t));
    tbb::parallel_sort(root.events.begin(), root.events.end());  // the build's one full sort
    root.budget = uint64_t(settings.max_references_per_triangle * double(n));
    const float log2n = n > 1 ? std::log2(float(n)) : 0.0f;
    const auto max_depth = std::min(kKdMaxDepth, uint32_t(settings.depth_base + settings.depth_per_log2 * log2n));

    KdTree tree;
    tree.bounds = root.voxel;
    Subtree built;
    KdBuilder(triangles, settings, max_depth).build(std::move(root), built);
    tree.nodes = std::move(built.nodes);
    tree.depth = built.depth;
    tree.leaf_blocks = leaf_blocks(tree.nodes, built.refs, triangles);
    return tree;
}

KdStats kd_stats(const KdTree& tree, uint64_t triangles) {
    KdStats s;
    s.nodes = tree.nodes.size();
    for (const KdNode& node : tree.nodes) {
        s.leaves += node.is_leaf();
        if (node.is_leaf()) s.references += node.count();
    }
    s.depth = tree.depth;
    s.refs_per_triangle = triangles ? double(s.references) / double(triangles) : 0.0;
    return s;
}

namespace {

// Sum over the subtree at `index` (voxel `voxel`) of eq. 1's numerator terms.
double sah_sum(const KdTree& tree, uint32_t index, const BBox& voxel, float inner, float triangle) {
    const KdNode& node = tree.nodes[index];
    const double area = voxel.area();
    if (node.is_leaf()) return triangle * double(node.count()) * area;
    BBox below = voxel, above = voxel;
    below.upper[node.axis()] = above.lower[node.axis()] = node.split;
    return inner * area + sah_sum(tree, index + 1, below, inner, triangle) +
           sah_sum(tree, node.above(), above, inner, triangle);
}

}  // namespace

double kd_sah_cost(const KdTree& tree, float inner, float triangle) {
    const double root = tree.bounds.area();
    if (tree.nodes.empty() || !(root > 0.0)) return 0.0;
    return sah_sum(tree, 0, tree.bounds, inner, triangle) / root;
}

}  // namespace canopy
