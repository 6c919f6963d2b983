#include "accel/builders/tree_rotations.h"

#include <algorithm>
#include <atomic>
#include <cmath>

namespace canopy {
namespace {

constexpr uint32_t kParallelGrain = 4 * 1024;  // triangles under a subtree worth a task
constexpr uint32_t kMaxHillClimbPasses = 200;  // caps the work; passes stop far earlier in practice
constexpr float kMinRelativeGain = 1e-6f;      // a rotation must gain this share of the node's area: no cycling
// Annealing schedule, our choice tuned on sponza: temperatures fall linearly from kStartTemperature to 0 over
// kAnnealPasses passes. Deltas are measured relative to the node's own area, so one temperature suits every
// level of the tree.
constexpr uint32_t kAnnealPasses = 96;
constexpr float kStartTemperature = 0.02f;
constexpr uint32_t kPassesPerRelayout = 8;  // rotations scatter subtrees in memory: lay them out again
constexpr uint64_t kAnnealSeed = 0x6b656e736c6572ull;

// Swapping subtrees a and b changes the sum of inner areas by delta (their new parents' areas; as in
// Kensler: the node's own box stays the same).
struct Rotation {
    uint32_t a, b;
    float delta;
};

// The rotations at n: each child with each grandchild under the other child, and the two distinct swaps of
// grandchildren on opposite sides.
int rotations_at(const MutableTree& tree, uint32_t n, Rotation out[6]) {
    int count = 0;
    const uint32_t child[2] = {tree[n].child[0], tree[n].child[1]};
    for (uint32_t near = 0; near < 2; ++near) {
        const MutableNode& far = tree[child[1 - near]];
        if (far.is_leaf()) continue;
        for (uint32_t g = 0; g < 2; ++g) {
            const float area = merge(tree[child[near]].bounds, tree[far.child[1 - g]].bounds).half_area();
            out[count++] = {child[near], far.child[g], area - far.bounds.half_area()};
        }
    }
    const MutableNode& left = tree[child[0]];
    const MutableNode& right = tree[child[1]];
    if (left.is_leaf() || right.is_leaf()) return count;
    for (uint32_t j = 0; j < 2; ++j) {
        const float new_left = merge(tree[right.child[j]].bounds, tree[left.child[1]].bounds).half_area();
        const float new_right = merge(tree[left.child[0]].bounds, tree[right.child[1 - j]].bounds).half_area();
        out[count++] = {left.child[0], right.child[j],
                        new_left + new_right - left.bounds.half_area() - right.bounds.half_area()};
    }
    return count;
}

void apply(MutableTree& tree, const Rotation& r) {
    tree.swap_subtrees(r.a, r.b);
    tree.refit(tree[r.a].parent);
    tree.refit(tree[r.b].parent);
}

uint64_t hill_climb_pass(MutableTree& tree) {
    std::atomic<uint64_t> applied{0};
    visit_inner_post_order(tree, [&](uint32_t n) {
        Rotation candidates[6];
        const int count = rotations_at(tree, n, candidates);
        if (count == 0) return;
        const Rotation* best = std::min_element(candidates, candidates + count,
                                                [](const Rotation& x, const Rotation& y) { return x.delta < y.delta; });
        if (best->delta < -kMinRelativeGain * tree.area(n)) {
            apply(tree, *best);
            applied.fetch_add(1, std::memory_order_relaxed);
        }
    }, kParallelGrain);
    return applied.load();
}

uint64_t mix(uint64_t x) {  // splitmix64's finaliser
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

void anneal_pass(MutableTree& tree, float temperature, uint64_t pass_key) {
    visit_inner_post_order(tree, [&](uint32_t n) {
        Rotation candidates[6];
        const int count = rotations_at(tree, n, candidates);
        const float area = tree.area(n);
        if (count == 0 || area <= 0.0f) return;
        const uint64_t random = mix(pass_key ^ mix(n));
        const Rotation& r = candidates[random % uint64_t(count)];
        const float relative = r.delta / area;
        const float uniform = float(mix(random) >> 40) * 0x1p-24f;
        if (relative <= 0.0f || uniform < std::exp(-relative / temperature)) apply(tree, r);
    }, kParallelGrain);
}

}  // namespace

void hill_climb(MutableTree& tree) {
    tree.relayout();
    for (uint32_t pass = 0; pass < kMaxHillClimbPasses && hill_climb_pass(tree) > 0; ++pass) {}
}

void anneal(MutableTree& tree, uint64_t seed) {
    for (uint32_t pass = 0; pass < kAnnealPasses; ++pass) {
        const float temperature = kStartTemperature * float(kAnnealPasses - pass) / float(kAnnealPasses);
        if (pass % kPassesPerRelayout == 0) tree.relayout();
        anneal_pass(tree, temperature, mix(seed + pass));
    }
    hill_climb(tree);
}

Bvh build_hillclimb(BuildInput&& input, const BuildSettings& settings) {
    MutableTree tree(build_start_tree(std::move(input), settings, "lbvh"));
    hill_climb(tree);
    return tree.to_bvh(settings);
}

Bvh build_anneal(BuildInput&& input, const BuildSettings& settings) {
    MutableTree tree(build_start_tree(std::move(input), settings, "lbvh"));
    MutableTree start = tree;
    anneal(tree, kAnnealSeed);
    if (tree.inner_area() <= start.inner_area()) return tree.to_bvh(settings);
    hill_climb(start);  // annealing ended above the start: never return a worse tree than hill climbing
    return start.to_bvh(settings);
}

}  // namespace canopy
