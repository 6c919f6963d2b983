#include "accel/wide_bvh.h"
#include "accel/parallel.h"
#include "accel/wide_bvh_writing.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <utility>

namespace canopy {
namespace {

using wide_writing::Cursor;
using wide_writing::Extent;
using wide_writing::put_triangle;
using wide_writing::stream;
using wide_writing::stream_fence;

// Marks the lanes past a merged subtree's last ref (Collapser::merges).
constexpr uint32_t kNoRef = 0xffffffffu;

// A wide node's children as binary nodes. Greedy (Ganestam and Doggett 2016, sec. 4.2): the binary node's two
// children, then repeatedly the inner child of largest surface area (the first of equals) replaced by its two
// children until there are N. Or as a CollapsePlan chose them.
template <int N>
class CollapsePlan;

template <int N>
struct WideChildren {
    std::array<uint32_t, N> node;
    int count = 0;
    uint32_t merged = 0;  // bit i: inner child i is written as one leaf of its subtree's triangles (Collapser)

    WideChildren(const Bvh& bvh, uint32_t index) {
        std::array<float, N> area;           // half area of an inner child; -1 for a leaf, never opened
        std::array<uint32_t, N> first_child;  // of an inner child
        auto put = [&](int slot, uint32_t child) {
            const BvhNode& c = bvh.nodes[child];
            node[slot] = child;
            area[slot] = c.is_leaf() ? -1.0f : c.bounds.half_area();
            first_child[slot] = c.index;
            // Opening is a chain of dependent loads: start fetching the children it may open next.
            if (!c.is_leaf()) __builtin_prefetch(&bvh.nodes[c.index]);
        };
        put(count++, bvh.nodes[index].index);
        put(count++, bvh.nodes[index].index + 1);
        while (count < N) {
            int widest = -1;
            float widest_area = -1.0f;
            for (int i = 0; i < count; ++i)
                if (area[i] > widest_area) widest = i, widest_area = area[i];
            if (widest < 0) break;
            const uint32_t first = first_child[widest];
            put(widest, first);
            put(count++, first + 1);
        }
    }
    // A root that is a leaf: one leaf child.
    explicit WideChildren(uint32_t leaf) : count(1) { node[0] = leaf; }
    // The children a CollapsePlan chose.
    WideChildren(const CollapsePlan<N>& plan, uint32_t index) : count(plan.children(index, node)) {}
};

// The least-cost wide tree over a binary one (Ylitie, Karras and Laine 2017, sec. 3.1). C(n, k), the least cost of
// binary subtree n as at most k children of one wide node, is A(n) b(n) C_block for a leaf of b(n) blocks, and else
//   C(n, 1) = min(A(n) C_block where n's triangles fit one block (n written as one leaf), A(n) C_node + S(n, N))
//   C(n, k) = min(C(n, k - 1), S(n, k)) for k > 1,   S(n, k) = min over 0 < i < k of C(left, i) + C(right, k - i),
// A being the surface area: each term is a node or block test times the chance that a ray makes it (eq. 1's
// reasoning). The choices that reach each minimum are kept per node; a wide node's children unfold from them.
template <int N>
class CollapsePlan {
public:
    // `may_merge`: whether a subtree may be written as one leaf (only where leaves are triangle blocks).
    CollapsePlan(const Bvh& bvh, bool enabled, bool may_merge, uint32_t lanes)
        : bvh_(bvh), may_merge_(may_merge), lanes_(lanes), parallel_(bvh.nodes.size() >= kParallelNodes) {
        if (!enabled || bvh.nodes.empty() || bvh.nodes[0].is_leaf()) return;
        choice_.resize(bvh.nodes.size());
        solve(0, 0);
    }

    bool enabled() const { return !choice_.empty(); }

    // Whether inner binary node n is written as one leaf of its subtree's triangles.
    bool merged(uint32_t n) const { return choice_[n].leaf; }

    // The children of the wide node made of inner binary node n, in depth-first order; returns how many.
    int children(uint32_t n, std::array<uint32_t, N>& out) const {
        int count = 0;
        const uint32_t left = bvh_.nodes[n].index;
        expand(left, choice_[n].split[N], out, count);
        expand(left + 1, N - choice_[n].split[N], out, count);
        return count;
    }

private:
    // Test costs of canopy's bvh8 kernel, relative: one 8-lane block test against one node test. Frames hardly move
    // with the block's cost between half and one and a half node tests, and equal costs traced fastest on the trees
    // where they differed (docs/results.md#builds-and-layouts).
    static constexpr float kNodeTest = 1.0f;
    static constexpr float kBlockTest = 1.0f;
    static constexpr size_t kParallelNodes = 16 * 1024;  // smaller trees are planned on one thread
    static constexpr uint32_t kParallelDepth = 10;        // levels whose two subtrees are planned concurrently

    using Costs = std::array<float, N + 1>;  // C(n, k) at k = 1..N
    struct Solved {
        Costs cost;
        uint32_t triangles;  // in the subtree, counted up to lanes + 1
    };
    struct Choice {
        std::array<uint8_t, N + 1> split{};  // S(n, k)'s share of the left child, at k = 2..N
        uint16_t fewer = 0;                   // bit k: C(n, k) = C(n, k - 1), so n takes fewer than k slots
        bool leaf = false;                    // C(n, 1) is one leaf of n's triangles
    };

    Solved solve(uint32_t n, uint32_t depth) {
        const BvhNode& node = bvh_.nodes[n];
        const float area = node.bounds.half_area();
        Solved solved;
        if (node.is_leaf()) {
            solved.cost.fill(area * kBlockTest * float((node.count + lanes_ - 1) / lanes_));
            solved.triangles = std::min(node.count, lanes_ + 1);
            return solved;
        }
        Solved left, right;
        const bool fork = parallel_ && depth < kParallelDepth;
        parallel::fork_join(fork ? 1 : 0, 1, [&] { left = solve(node.index, depth + 1); },
                            [&] { right = solve(node.index + 1, depth + 1); });
        Choice& choice = choice_[n];
        const Costs shared = split_costs(left.cost, right.cost, choice.split);
        solved.triangles = std::min(left.triangles + right.triangles, lanes_ + 1);
        const float as_node = area * kNodeTest + shared[N];
        const float as_leaf = may_merge_ && solved.triangles <= lanes_ ? area * kBlockTest : std::numeric_limits<float>::infinity();
        choice.leaf = as_leaf < as_node;
        solved.cost[1] = std::min(as_leaf, as_node);
        for (int k = 2; k <= N; ++k) {
            const bool fewer = solved.cost[k - 1] <= shared[k];
            solved.cost[k] = fewer ? solved.cost[k - 1] : shared[k];
            choice.fewer |= uint16_t(uint16_t(fewer) << k);
        }
        return solved;
    }

    typedef float Lanes __attribute__((vector_size(32)));
    typedef int32_t Ints __attribute__((vector_size(32)));

    // Lane j holds lane j - I of `lanes`, or `fill`'s where j < I: the lanes moved up by I, one constant permute
    // (__builtin_shufflevector, which GCC and Clang both take; indices from 8 pick `fill`).
    template <int I>
    static Lanes shifted_up(Lanes lanes, Lanes fill) {
        return [&]<int... J>(std::integer_sequence<int, J...>) {
            return __builtin_shufflevector(lanes, fill, (J >= I ? J - I : 8 + J)...);
        }(std::make_integer_sequence<int, 8>{});
    }

    // S(n, k) for every k at once, and the left child's share that reaches each: lane j stands for k = j + 1, and
    // for each share i, lane j of the shifted costs is C(right, k - i), +inf where k - i < 1, so one vector add makes
    // every k's sum (one k at a time, the sums were scalar chains of dependent minima, a slower plan of the same tree:
    // docs/results.md#builds-and-layouts). The shifts are register permutes: unaligned loads from a freshly written
    // array waited for their stores each time. Shares are tried in increasing order and a later one wins only when
    // strictly cheaper, as one k at a time, so the choices are the scalar ones.
    static Costs split_costs(const Costs& left, const Costs& right, std::array<uint8_t, N + 1>& split) {
        static_assert(N <= 8, "one 8-lane vector holds every k");
        constexpr float inf = std::numeric_limits<float>::infinity();
        const Lanes infinite = Lanes{} + inf;
        Lanes right_lanes = infinite;  // lane j: C(right, j + 1)
        std::memcpy(&right_lanes, right.data() + 1, sizeof(float) * N);
        Lanes best = infinite;
        Ints share = Ints{} + 1;
        const auto try_share = [&]<int I>() {
            const Lanes cost = left[I] + shifted_up<I>(right_lanes, infinite);
            const Ints cheaper = cost < best;
            share = cheaper ? Ints{} + I : share;
            best = cheaper ? cost : best;
        };
        [&]<int... I>(std::integer_sequence<int, I...>) {
            (try_share.template operator()<I + 1>(), ...);  // shares 1 to N - 1, in order
        }(std::make_integer_sequence<int, N - 1>{});
        Costs out;
        out[0] = inf;
        for (int j = 0; j < N; ++j) out[j + 1] = best[j], split[j + 1] = uint8_t(share[j]);
        return out;
    }

    // Appends binary subtree n given k slots: n itself when it takes one, else its children's shares.
    void expand(uint32_t n, int k, std::array<uint32_t, N>& out, int& count) const {
        if (!bvh_.nodes[n].is_leaf()) {
            const Choice& c = choice_[n];
            while (k > 1 && (c.fewer >> k & 1)) --k;
            if (k > 1) {
                const uint32_t left = bvh_.nodes[n].index;
                expand(left, c.split[k], out, count);
                expand(left + 1, k - c.split[k], out, count);
                return;
            }
        }
        out[count++] = n;
    }

    const Bvh& bvh_;
    const bool may_merge_;
    const uint32_t lanes_;
    const bool parallel_;
    std::vector<Choice> choice_;  // by binary node; empty when the plan is not used
};

// Collapses so that subtrees are written in parallel yet land exactly where the serial depth-first order puts
// them: a node's inner children take consecutive slots, then each child's subtree follows in turn (siblings sit
// next to each other as the traversal visits them), and leaf entries follow the same order. A first pass measures
// every subtree's extent, keeping the wide nodes of each subtree below the top levels in depth-first order; the
// second writes the top levels and then replays those subtrees concurrently, each from its own cursor, without
// opening binary nodes again.
//
// The children of each wide node come from a CollapsePlan (the optimal method) or greedily (WideChildren). With shared
// blocks, an inner child is written as one leaf of its subtree's triangles, in depth-first order, where the plan chose
// that, or greedily where its subtree is at most a block's lanes of one-triangle leaves: its wide node would hold only
// those leaves, and a ray that reaches it pays a node test for the box tests the block test makes anyway (most of an
// LBVH's greedy BVH8 nodes: docs/results.md#builds-and-layouts). The first pass finds such a subtree's refs by a walk
// (or, for an LBVH, from its subtrees' ref ranges), and keeps them for the second, which reads them in order and
// fetches their triangles ahead.
template <int N, class LeafSink>
class Collapser {
    static constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    // A merged subtree's refs in depth-first order, kNoRef past the last; all kNoRef for a child not merged.
    using Refs = std::array<uint32_t, kLanes>;

    // A subtree below the top levels: its wide nodes in depth-first order, and the refs of their merged children
    // in the same order (node by node, child by child).
    struct Recorded {
        std::vector<WideChildren<N>> nodes;
        std::vector<Refs> merged;
    };

public:
    Collapser(const Bvh& bvh, WideNodes<N>& nodes, const PlaneFrame& frame, uint32_t (*entries)(int, uint32_t),
              LeafSink& sink, CollapseMethod method)
        : bvh_(bvh), plan_(bvh, method == CollapseMethod::Optimal && N > 2, kMerges, kLanes), nodes_(nodes),
          frame_(frame), entries_(entries), sink_(sink),
          top_depth_(bvh.nodes.size() < kParallelNodes ? 0 : kTopDepth),
          top_extents_(slot_of(top_depth_ + 1, 0)), top_merged_(top_extents_.size()),
          subtrees_(slot_of(top_depth_ + 1, 0) - slot_of(top_depth_, 0)) {}

    // Returns the extent of the whole tree; the sink is told it (`reserve`) before any leaf arrives.
    Extent run() {
        const bool lone_leaf = bvh_.nodes[0].is_leaf();
        const Extent total = lone_leaf ? own_extent(WideChildren<N>(0)) : measure(0, 0, 0);
        nodes_.clear();
        nodes_.resize(total.nodes);
        sink_.reserve(total);
        Cursor at{1, 0, 0};
        if (lone_leaf) {
            write_node(WideChildren<N>(0), 0, at, nullptr);
            stream_fence();
        } else {
            fill(0, 0, 0, 0, at);
        }
        return total;
    }

private:
    // Binary trees smaller than this collapse on one thread.
    static constexpr size_t kParallelNodes = 16 * 1024;
    static constexpr uint32_t kTopDepth = wide_writing::kTopDepth<N>;
    // Merged leaves ahead of the one being written whose triangles are fetched.
    static constexpr size_t kPrefetchMerged = 4;

    static constexpr auto slot_of = wide_writing::top_slot<N>;

    // The extent of the wide subtree rooted at inner binary node `index` (not merged), reached from the root by
    // `path`.
    Extent measure(uint32_t index, uint32_t depth, uint32_t path) {
        if (depth == top_depth_) return record(index, subtrees_[path]);
        WideChildren<N> children = children_of(index);
        for (int i = 0; i < children.count; ++i) {
            Refs& refs = top_merged_[slot_of(depth + 1, path * N + uint32_t(i))];
            if (merges(children.node[i], refs)) children.merged |= 1u << i;
        }
        parallel::for_each(size_t(children.count), 1, [&](size_t i) {
            const uint32_t slot = slot_of(depth + 1, path * N + uint32_t(i));
            if (is_node(children, int(i))) top_extents_[slot] = measure(children.node[i], depth + 1, path * N + uint32_t(i));
        });
        Extent total = own_extent(children);
        for (int i = 0; i < children.count; ++i)
            if (is_node(children, i)) total += top_extents_[slot_of(depth + 1, path * N + uint32_t(i))];
        return total;
    }

    // Measures a subtree below the top levels (its root not merged), appending its wide nodes in depth-first order.
    Extent record(uint32_t index, Recorded& out) {
        WideChildren<N> children = children_of(index);
        if (!has_ranges()) prefetch_grandchildren(children);
        for (int i = 0; i < children.count; ++i) {
            Refs refs;
            if (merges(children.node[i], refs)) {
                children.merged |= 1u << i;
                out.merged.push_back(refs);
            }
        }
        out.nodes.push_back(children);
        Extent total = own_extent(children);
        for (int i = 0; i < children.count; ++i)
            if (is_node(children, i)) total += record(children.node[i], out);
        return total;
    }

    // A wide node's children, as the plan chose them or greedily.
    WideChildren<N> children_of(uint32_t index) const {
        return plan_.enabled() ? WideChildren<N>(plan_, index) : WideChildren<N>(bvh_, index);
    }

    // Whether binary node `index` is an inner node written as one leaf: one the plan merged, or greedily one whose
    // subtree is at most a block's lanes of one-triangle leaves. If so, `refs` receives its refs in depth-first
    // order, else it is all kNoRef. The walk stops at the first leaf past a block's lanes (its stack never grows
    // past the lanes' count plus one on a subtree that merges).
    bool merges(uint32_t index, Refs& refs) const {
        refs.fill(kNoRef);
        if (!kMerges || bvh_.nodes[index].is_leaf()) return false;
        if (plan_.enabled() && !plan_.merged(index)) return false;
        if (has_ranges()) {  // no walk: the builder knows the subtree's refs
            const SubtreeRefs subtree = bvh_.one_ref_leaves[index];
            if (subtree.count > kLanes) return false;
            for (uint32_t k = 0; k < subtree.count; ++k) refs[k] = subtree.first + k;
            return true;
        }
        Refs found = refs;
        std::array<uint32_t, kLanes + 2> stack;
        uint32_t n = 0;
        size_t sp = 0;
        stack[sp++] = index;
        while (sp) {
            const BvhNode& node = bvh_.nodes[stack[--sp]];
            if (node.is_leaf()) {
                if ((node.count != 1 && !plan_.enabled()) || n + node.count > kLanes) return false;
                for (uint32_t k = 0; k < node.count; ++k) found[n++] = node.index + k;
            } else {
                if (sp + 2 > stack.size()) return false;
                stack[sp++] = node.index + 1;
                stack[sp++] = node.index;
            }
        }
        refs = found;
        return true;
    }

    // Whether the tree carries its subtrees' ref ranges (Bvh::one_ref_leaves), which replace the walks of merges().
    bool has_ranges() const { return bvh_.one_ref_leaves.size() == bvh_.nodes.size(); }

    // The walks of merges() are chains of dependent loads, bound by latency: fetch the next level of every child's
    // subtree at once (WideChildren fetched the children's own children).
    void prefetch_grandchildren(const WideChildren<N>& children) const {
        for (int i = 0; i < children.count; ++i) {
            const BvhNode& c = bvh_.nodes[children.node[i]];
            if (c.is_leaf()) continue;
            for (uint32_t k = 0; k < 2; ++k) {
                const BvhNode& g = bvh_.nodes[c.index + k];
                if (!g.is_leaf()) __builtin_prefetch(&bvh_.nodes[g.index]);
            }
        }
    }

    // Whether child i of a wide node is written as a wide node of its own.
    bool is_node(const WideChildren<N>& children, int i) const {
        return !(children.merged >> i & 1) && !bvh_.nodes[children.node[i]].is_leaf();
    }

    // What a wide node takes itself: its slot, its leaves and their entries.
    Extent own_extent(const WideChildren<N>& children) const {
        Extent own{1, 0, 0};
        uint32_t shared = 0;
        for (int i = 0; i < children.count; ++i) {
            const BvhNode& c = bvh_.nodes[children.node[i]];
            if (children.merged >> i & 1) {
                ++own.leaves, ++own.entries;
                continue;
            }
            if (!c.is_leaf()) continue;
            ++own.leaves;
            if (shares_block(c))
                ++shared;
            else
                own.entries += entries_(N, c.count);
        }
        own.entries += (shared + kLanes - 1) / kLanes;
        return own;
    }

    // Writes the top-level subtree rooted at binary node `index` into slot `self`, its descendants from `at`: each
    // inner child's subtree starts where its earlier siblings' extents end, so they are written concurrently.
    void fill(uint32_t index, uint32_t self, uint32_t depth, uint32_t path, Cursor at) {
        if (depth == top_depth_) return replay(subtrees_[path], self, at);
        WideChildren<N> children = children_of(index);
        std::array<Refs, N> merged;
        int merged_count = 0;
        for (int i = 0; i < children.count; ++i) {
            const Refs& refs = top_merged_[slot_of(depth + 1, path * N + uint32_t(i))];
            if (refs[0] == kNoRef) continue;
            children.merged |= 1u << i;
            merged[merged_count++] = refs;
        }
        const std::array<uint32_t, N> slots = write_node(children, self, at, merged.data());
        stream_fence();
        std::array<Cursor, N> start;
        for (int i = 0; i < children.count; ++i) {
            if (!is_node(children, i)) continue;
            start[i] = at;
            const Extent& e = top_extents_[slot_of(depth + 1, path * N + uint32_t(i))];
            at += Extent{e.nodes - 1, e.entries, e.leaves};  // its root took a slot in write_node
        }
        parallel::for_each(size_t(children.count), 1, [&](size_t i) {
            if (is_node(children, int(i)))
                fill(children.node[i], slots[i], depth + 1, path * N + uint32_t(i), start[i]);
        });
    }

    // Writes a recorded subtree from slot `self` in depth-first order: each node takes the slot its parent gave it,
    // kept on a stack so that the first child's subtree comes next.
    void replay(const Recorded& recorded, uint32_t self, Cursor at) {
        const std::vector<WideChildren<N>>& records = recorded.nodes;
        const Refs* merged = recorded.merged.data();
        const Refs* const merged_end = merged + recorded.merged.size();
        std::vector<uint32_t> slots{self};
        for (size_t r = 0; r < records.size(); ++r) {
            // Fetch ahead what write_node reads at random: binary children two records on, and the leaf
            // contents (every triangle, not only each leaf's first, which measured faster:
            // docs/results.md#builds-and-layouts) of the next record, whose children are in cache by now.
            if (r + 2 < records.size())
                for (int i = 0; i < records[r + 2].count; ++i) __builtin_prefetch(&bvh_.nodes[records[r + 2].node[i]]);
            if (r + 1 < records.size())
                for (int i = 0; i < records[r + 1].count; ++i) {
                    const BvhNode& c = bvh_.nodes[records[r + 1].node[i]];
                    if (c.is_leaf())
                        for (uint32_t k = 0; k < c.count; ++k) sink_.prefetch(c.index + k);
                }
            const WideChildren<N>& children = records[r];
            const int merged_here = std::popcount(children.merged);
            for (const Refs* ahead = merged + kPrefetchMerged; ahead < std::min(merged + kPrefetchMerged + merged_here, merged_end); ++ahead)
                for (uint32_t lane = 0; lane < kLanes && (*ahead)[lane] != kNoRef; ++lane) sink_.prefetch((*ahead)[lane]);
            const uint32_t slot = slots.back();
            slots.pop_back();
            const std::array<uint32_t, N> child = write_node(children, slot, at, merged);
            merged += merged_here;
            for (int i = children.count - 1; i >= 0; --i)
                if (is_node(children, i)) slots.push_back(child[i]);
        }
        stream_fence();
    }

    // Writes node `self`: inner children take the next node slots, leaf children the next entries, the
    // one-triangle leaves among them sharing blocks where the sink shares them; merged children take the refs
    // from `merged` in child order. Returns the node's `child` slots, so that callers need not read back what was
    // streamed.
    std::array<uint32_t, N> write_node(const WideChildren<N>& children, uint32_t self, Cursor& at, const Refs* merged) {
        WideNode<N> node;  // assembled aside and streamed, as leaf blocks are
        uint32_t shared_block = 0, shared_lanes = 0;  // the block one-triangle leaves are filling, its lanes in use
        Refs shared_refs;                              // their refs: the block is written when full or at the end
        for (int i = 0; i < N; ++i) {
            if (i >= children.count) {
                frame_.set_box(node, i, BBox{});  // lower = +inf, upper = -inf: never hit
                node.child[i] = WideNode<N>::kEmpty;
                node.count[i] = 0;
                continue;
            }
            const BvhNode& c = bvh_.nodes[children.node[i]];
            frame_.set_box(node, i, c.bounds);
            node.count[i] = c.count;
            if (children.merged >> i & 1) {
                if constexpr (kMerges) {
                    node.child[i] = at.entries++;
                    node.count[i] = sink_.gathered(node.child[i], *merged++);
                    ++at.leaves;
                }
            } else if (!c.is_leaf()) {
                node.child[i] = at.nodes++;
            } else if (shares_block(c)) {
                if constexpr (kMerges) {
                    if (shared_lanes == 0) shared_block = at.entries++, shared_refs.fill(kNoRef);
                    node.child[i] = shared_block;
                    ++at.leaves;
                    shared_refs[shared_lanes++] = c.index;
                    if (shared_lanes == kLanes) sink_.gathered(shared_block, shared_refs), shared_lanes = 0;
                }
            } else {
                node.child[i] = at.entries;
                sink_.own(at.leaves++, LeafRun{at.entries, c.index, c.count});
                at.entries += entries_(N, c.count);
            }
        }
        if constexpr (kMerges)
            if (shared_lanes > 0) sink_.gathered(shared_block, shared_refs);
        stream(&nodes_[self], node);
        return std::to_array(node.child);
    }

    static constexpr bool kMerges = LeafSink::kSharesBlocks;

    static bool shares_block(const BvhNode& c) { return LeafSink::kSharesBlocks && c.count == 1; }

    const Bvh& bvh_;
    const CollapsePlan<N> plan_;  // enabled for the optimal method at widths above 2 (at 2 both methods agree)
    WideNodes<N>& nodes_;
    const PlaneFrame frame_;
    uint32_t (*entries_)(int, uint32_t);
    LeafSink& sink_;
    const uint32_t top_depth_;
    std::vector<Extent> top_extents_;  // by top-level slot (slot_of)
    std::vector<Refs> top_merged_;     // by top-level slot: the refs of a merged child, else all kNoRef
    std::vector<Recorded> subtrees_;   // by path at top_depth_
};

// Keeps the leaves in emission order, one run each, for a caller whose leaves hold something else than triangles.
struct RunList {
    static constexpr bool kSharesBlocks = false;
    std::vector<LeafRun> runs;

    void reserve(const Extent& total) { runs.resize(total.leaves); }
    void own(uint32_t leaf, const LeafRun& run) { runs[leaf] = run; }
    void prefetch(uint32_t) const {}  // leaves are filled later, by the caller
};

// Copies each leaf's triangles into the wide tree as soon as its entries are known. With SIMD blocks the
// one-triangle leaves of a node share blocks, a lane each (see wide_bvh.h).
template <int N>
struct TriangleLeaves {
    static constexpr bool kSharesBlocks = N > 2;
    static constexpr uint32_t kLanes = uint32_t(block_lanes(N));
    using Leaf = typename WideBvh<N>::Leaf;
    WideBvh<N>& out;
    const Bvh& bvh;
    std::span<const Triangle> triangles;

    void reserve(const Extent& total) { out.leaves.resize(total.entries); }

    // The triangle of one ref (both cache lines it may span).
    void prefetch(uint32_t ref) const {
        const char* t = reinterpret_cast<const char*>(&triangles[bvh.refs[ref]]);
        __builtin_prefetch(t);
        __builtin_prefetch(t + sizeof(Triangle) - 1);
    }

    void own(uint32_t, const LeafRun& run) {
        if constexpr (N == 2) {
            for (uint32_t i = 0; i < run.count; ++i) {
                const uint32_t prim = bvh.refs[run.first_ref + i];
                put_triangle(out.leaves[run.first_entry + i], prim, triangles[prim]);
            }
        } else {
            for (uint32_t first = 0; first < run.count; first += kLanes) {
                std::array<uint32_t, kLanes> refs;
                refs.fill(kNoRef);
                for (uint32_t lane = 0; lane < kLanes && first + lane < run.count; ++lane) refs[lane] = run.first_ref + first + lane;
                gathered(run.first_entry + first / kLanes, refs);
            }
        }
    }

    // One block of the triangles of `refs` (up to the first kNoRef), a lane each in order; returns how many. The
    // block is assembled aside and then streamed to the leaf array, which traversal reads only later: a plain store
    // would first fetch every line it writes.
    uint32_t gathered(uint32_t entry, const std::array<uint32_t, kLanes>& refs) {
        static const Leaf empty = wide_writing::empty_block<kLanes>();
        Leaf block = empty;
        uint32_t lane = 0;
        for (; lane < kLanes && refs[lane] != kNoRef; ++lane) {
            const uint32_t prim = bvh.refs[refs[lane]];
            put_triangle(block, lane, prim, triangles[prim]);
        }
        stream(&out.leaves[entry], block);
        return lane;
    }
};

}  // namespace

CollapseMethod parse_collapse_method(const std::string& name) {
    if (name == "optimal") return CollapseMethod::Optimal;
    if (name == "greedy") return CollapseMethod::Greedy;
    if (name == "direct") return CollapseMethod::Direct;
    throw std::invalid_argument("unknown collapse '" + name + "' (known: optimal, greedy, direct)");
}

// Direct is lbvh's own emission from Morton codes: there is no binary tree it could collapse.
void check_collapsible(CollapseMethod method) {
    if (method == CollapseMethod::Direct)
        throw std::invalid_argument("collapse 'direct' is lbvh's wide tree built from its Morton codes, not a collapse of a binary tree");
}

template <int N>
std::vector<LeafRun> collapse_nodes(const Bvh& bvh, WideNodes<N>& nodes, const PlaneFrame& frame,
                                    uint32_t (*entries)(int, uint32_t), uint32_t& total_entries, CollapseMethod method) {
    check_collapsible(method);
    RunList list;
    total_entries = Collapser<N, RunList>(bvh, nodes, frame, entries, list, method).run().entries;
    return std::move(list.runs);
}

template <int N>
WideBvh<N> collapse(const Bvh& bvh, std::span<const Triangle> triangles, CollapseMethod method,
                    std::optional<Vec3> origin) {
    check_collapsible(method);
    WideBvh<N> out;
    if (bvh.nodes.empty()) return out;
    out.bounds = bvh.nodes[0].bounds;
    out.frame = origin ? PlaneFrame::at(*origin, out.bounds) : PlaneFrame::centred(out.bounds);
    TriangleLeaves<N> leaves{out, bvh, triangles};
    Collapser<N, TriangleLeaves<N>>(bvh, out.nodes, out.frame, &leaf_entries, leaves, method).run();
    return out;
}

template <int N>
void permute_nodes(WideBvh<N>& tree, uint64_t seed) {
    const size_t count = tree.nodes.size();
    if (count < 3) return;
    std::vector<uint32_t> place(count);  // place[old index] = new index; the root stays first
    std::iota(place.begin(), place.end(), 0u);
    std::mt19937_64 rng(seed);
    std::shuffle(place.begin() + 1, place.end(), rng);
    WideNodes<N> moved(count);
    for (size_t old = 0; old < count; ++old) {
        WideNode<N> node = tree.nodes[old];
        for (int i = 0; i < N; ++i)
            if (!node.is_empty(i) && !node.is_leaf(i)) node.child[i] = place[node.child[i]];
        moved[place[old]] = node;
    }
    tree.nodes = std::move(moved);
}

template void permute_nodes<2>(WideBvh<2>&, uint64_t);
template void permute_nodes<4>(WideBvh<4>&, uint64_t);
template void permute_nodes<8>(WideBvh<8>&, uint64_t);
template std::vector<LeafRun> collapse_nodes<2>(const Bvh&, WideNodes<2>&, const PlaneFrame&, uint32_t (*)(int, uint32_t), uint32_t&,
                                                   CollapseMethod);
template std::vector<LeafRun> collapse_nodes<4>(const Bvh&, WideNodes<4>&, const PlaneFrame&, uint32_t (*)(int, uint32_t), uint32_t&,
                                                   CollapseMethod);
template std::vector<LeafRun> collapse_nodes<8>(const Bvh&, WideNodes<8>&, const PlaneFrame&, uint32_t (*)(int, uint32_t), uint32_t&,
                                                   CollapseMethod);
template WideBvh<2> collapse<2>(const Bvh&, std::span<const Triangle>, CollapseMethod, std::optional<Vec3>);
template WideBvh<4> collapse<4>(const Bvh&, std::span<const Triangle>, CollapseMethod, std::optional<Vec3>);
template WideBvh<8> collapse<8>(const Bvh&, std::span<const Triangle>, CollapseMethod, std::optional<Vec3>);

}  // namespace canopy
