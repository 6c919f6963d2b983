#include "accel/builders/agglomerative.h"

#include "accel/cluster_tree.h"
#include "accel/morton.h"
#include "accel/parallel.h"

#include <bit>
#include <limits>
#include <queue>

namespace canopy {
namespace {

constexpr size_t kGrain = 1024;
constexpr uint32_t kNone = 0xffffffffu;
constexpr uint32_t kSeeds = 8;  // slots either side tried before the tree search

// Walter et al.'s distance for BVH clusters: the surface area (here the half area) of the box around both.
float distance(const BBox& a, const BBox& b) { return merge(a, b).half_area(); }

// A lower bound of d(A, B) over every B whose centre lies in `centres` and whose half extent is at least
// `min_half` on each axis: on each axis the merged box spans A and B's interval, narrowest for B's centre
// nearest A's centre. Bounding centres rather than boxes (a tree over cluster positions, like Walter et al.'s
// kd-tree) keeps a few large triangles from making the bound useless across the whole scene; the least half
// extent keeps large clusters that all overlap (long parallel needles, big random triangles) from doing so.
float distance_bound(const BBox& a, const BBox& centres, const Vec3& min_half) {
    const Vec3 nearest_centre = glm::clamp(a.center(), centres.lower, centres.upper);
    return merge(a, BBox{nearest_centre - min_half, nearest_centre + min_half}).half_area();
}

// The auxiliary tree of the nearest-neighbour search (the role of Walter et al.'s kd-tree): a complete binary
// tree over slots in Morton order of the initial clusters, each node the box of the centres of the live
// clusters below it with their least half extent per axis (a slot keeps its cluster's box as well, for the
// exact distance). A merged cluster takes its first part's slot, the second part's slot empties, and both
// paths to the root are refit, so the boxes stay exact as clusters grow and disappear.
class SlotTree {
public:
    explicit SlotTree(uint32_t slots)
        : size_(std::bit_ceil(std::max(slots, 2u))),
          centres_(2 * size_t(size_)),
          min_half_(2 * size_t(size_), Vec3(std::numeric_limits<float>::infinity())),
          boxes_(size_) {}

    // Fills the leaves then every inner node, without refitting paths one by one.
    template <class BoxOf>
    void assign_all(uint32_t slots, BoxOf&& box_of) {
        for (uint32_t s = 0; s < slots; ++s) set_leaf(s, box_of(s));
        for (uint32_t node = size_ - 1; node >= 1; --node) refit(node);
    }

    // An empty box empties the slot.
    void set(uint32_t slot, const BBox& box) {
        set_leaf(slot, box);
        for (uint32_t node = (size_ + slot) / 2; node >= 1; node /= 2) refit(node);
    }

    // The slot, other than `self`, whose cluster is nearest to `box`. Of equally near ones, the first in the
    // search order: that order depends only on the tree, so the answer does not depend on threads, and a
    // cluster inside a big one's box ends the search as soon as it is found. Where box areas overflow float
    // (scenes beyond about 1e19), distances are infinite: the first live slot found then stands, so there is
    // always an answer while another cluster lives.
    std::pair<uint32_t, float> nearest(const BBox& box, uint32_t self) const {
        uint32_t best = kNone;
        float best_distance = std::numeric_limits<float>::infinity();
        const auto nearer = [&](float d) { return best == kNone || d < best_distance; };
        // Neighbours in Morton order are usually near: starting from the best of them prunes most of the tree.
        for (uint32_t slot = self > kSeeds ? self - kSeeds : 0; slot < std::min(self + kSeeds + 1, size_); ++slot) {
            if (slot == self || boxes_[slot].empty()) continue;
            const float d = distance(box, boxes_[slot]);
            if (nearer(d)) best = slot, best_distance = d;
        }
        uint32_t stack[64];
        int top = 0;
        stack[top++] = 1;
        while (top > 0) {
            const uint32_t node = stack[--top];
            if (centres_[node].empty() || (best != kNone && bound(box, node) >= best_distance)) continue;
            if (node >= size_) {
                const uint32_t slot = node - size_;
                const float d = distance(box, boxes_[slot]);
                if (slot != self && nearer(d)) best = slot, best_distance = d;
                continue;
            }
            // Nearer child on top, so it is searched first and tightens the bound for the other.
            const float left = bound(box, 2 * node), right = bound(box, 2 * node + 1);
            stack[top++] = left <= right ? 2 * node + 1 : 2 * node;
            stack[top++] = left <= right ? 2 * node : 2 * node + 1;
        }
        return {best, best_distance};
    }

private:
    // Half extents a hair under the exact ones, so that rounding in the bound never prunes an equally near slot.
    static constexpr float kShrink = 1.0f - 0x1p-20f;

    void set_leaf(uint32_t slot, const BBox& box) {
        boxes_[slot] = box;
        centres_[size_ + slot] = box.empty() ? BBox{} : BBox{box.center(), box.center()};
        min_half_[size_ + slot] = box.empty() ? Vec3(std::numeric_limits<float>::infinity()) : 0.5f * kShrink * box.extent();
    }

    void refit(uint32_t node) {
        centres_[node] = merge(centres_[2 * node], centres_[2 * node + 1]);
        min_half_[node] = glm::min(min_half_[2 * node], min_half_[2 * node + 1]);
    }

    float bound(const BBox& box, uint32_t node) const { return distance_bound(box, centres_[node], min_half_[node]); }

    uint32_t size_;              // leaves: slots rounded up to a power of two
    std::vector<BBox> centres_;  // heap order: node k has children 2k and 2k + 1, leaves from size_ on
    std::vector<Vec3> min_half_;  // heap order: the least half extent per axis of the live clusters below
    std::vector<BBox> boxes_;    // by slot: the live cluster's box
};

// A heap entry: cluster `cluster`'s nearest neighbour was `neighbour`, at distance d. Entries whose cluster
// has merged are dropped; those whose neighbour has merged are a lower bound (merged boxes only grow) and
// are renewed when they come up.
struct Candidate {
    float d;
    uint32_t cluster, neighbour;
    bool operator>(const Candidate& o) const {
        return d != o.d ? d > o.d : (cluster != o.cluster ? cluster > o.cluster : neighbour > o.neighbour);
    }
};

class Agglomerative {
public:
    explicit Agglomerative(const std::vector<PrimRef>& refs)
        : refs_(refs), tree_(refs), n_(uint32_t(refs.size())), slots_(n_) {}

    Bvh build() {
        const MortonOrder sorted = sort_by_morton_code(refs_);
        cluster_at_ = sorted.order;  // slot -> cluster
        slot_of_.assign(2 * size_t(n_) - 1, kNone);
        for (uint32_t s = 0; s < n_; ++s) slot_of_[cluster_at_[s]] = s;
        slots_.assign_all(n_, [&](uint32_t s) { return tree_.bounds(cluster_at_[s]); });
        std::vector<Candidate> initial(n_);
        parallel::for_each(n_, kGrain, [&](size_t s) { initial[s] = nearest(cluster_at_[s]); });
        std::priority_queue<Candidate, std::vector<Candidate>, std::greater<>> heap(std::greater<>{}, std::move(initial));
        // Walter et al.'s heap-based greedy clustering: the smallest entry whose two clusters are both live is the
        // closest pair of all, since every other entry is exact or a lower bound.
        for (uint32_t live = n_; live > 1;) {
            const Candidate c = heap.top();
            heap.pop();
            if (merged(c.cluster)) continue;
            if (merged(c.neighbour)) {
                heap.push(nearest(c.cluster));
                continue;
            }
            const uint32_t joined = merge(c.cluster, c.neighbour);
            if (--live > 1) heap.push(nearest(joined));
        }
        return tree_.to_bvh(refs_);
    }

private:
    bool merged(uint32_t cluster) const { return slot_of_[cluster] == kNone; }

    Candidate nearest(uint32_t cluster) const {
        const auto [slot, d] = slots_.nearest(tree_.bounds(cluster), slot_of_[cluster]);
        return {d, cluster, cluster_at_[slot]};
    }

    uint32_t merge(uint32_t a, uint32_t b) {
        const uint32_t joined = tree_.merge(a, b);
        const uint32_t slot = slot_of_[a];
        slots_.set(slot, tree_.bounds(joined));
        slots_.set(slot_of_[b], BBox{});
        cluster_at_[slot] = joined;
        slot_of_[joined] = slot;
        slot_of_[a] = slot_of_[b] = kNone;
        return joined;
    }

    const std::vector<PrimRef>& refs_;
    ClusterTree tree_;
    const uint32_t n_;
    SlotTree slots_;
    std::vector<uint32_t> cluster_at_, slot_of_;  // slot -> live cluster; cluster -> slot (kNone once merged)
};

}  // namespace

// One triangle per leaf: the leaf size and costs do not enter the clustering.
Bvh build_agglomerative(BuildInput&& input, const BuildSettings&) {
    if (input.refs.empty()) return {};
    return Agglomerative(input.refs).build();
}

}  // namespace canopy
