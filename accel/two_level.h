#pragma once
// Two-level BVHs over objects and instances, and partial re-braiding (Benthin, Woop, Wald and Áfra 2017,
// "Improved Two-Level BVHs using Partial Re-Braiding"). Each object gets its own BVH in object space; instances
// place objects with affine transforms; the top level is built over BRefs (sec. 3.2): references to nodes of
// object BVHs with their world bounds. The plain two-level top level keeps one BRef per instance, at the object
// root; re-braiding opens BRefs where objects overlap (sec. 4), so the top level reaches into object trees.
// Beyond the paper, re-braiding here also opens object leaves into triangles (sec. 7's future work), opens the
// widest BRefs first, bounds a transformed node by its children's transformed boxes, and opens a transformed
// node only where that does not add instance entries (two_level.cpp says why, with measurements).
#include "accel/builder.h"
#include "accel/wide_bvh.h"

#include <glm/mat4x4.hpp>

#include <vector>

namespace canopy {

// An object BVH placed in the world. prim_offset turns the object's triangle ids into scene-wide ones.
struct TwoLevelInstance {
    uint32_t object = 0;
    glm::mat4 to_world{1.0f};
    uint32_t prim_offset = 0;
};

struct TwoLevelInput {
    std::vector<std::vector<Triangle>> objects;  // object-space triangles; an object's prims are 0..n-1
    std::vector<TwoLevelInstance> instances;
};

enum class TopLevel { TwoLevel, Rebraid };

struct TwoLevelSettings {
    std::string blas_builder = "binned";  // any registered builder, for every object BVH
    BuildSettings blas;                   // their settings (leaf_block follows the kernel)
    TopLevel top = TopLevel::Rebraid;
    // Sec. 4.2: open BRefs wider than this share of the segment's extent. The paper's 10% left crytek-sponza's
    // re-braided frames slower than its flat tree's, half of the extent faster, and the other scenes' trees the same
    // (docs/results.md#closing-the-two-level-gap-on-crytek-sponza-re-braiding-paper-table-1).
    float open_extent = 0.5f;
    uint32_t bins = 32;                   // of the top level's binned SAH, 2 to 64
    uint32_t brefs_per_placement = 0;     // sec. 5.2's BRef array size over the placements; 0: the paper's heuristic
    CollapseMethod collapse = CollapseMethod::Optimal;  // of the object trees and the top level
};

// The ray's way into an instance: world to object space, or nothing for an identity placement. prim_offset is
// added to the ids of triangles hit through this instance (its object's leaves hold ids offset by their
// ObjectTree::prim_base already).
struct PlacedObject {
    uint32_t object = 0;
    uint32_t prim_offset = 0;
    bool identity = true;
    float world_to_object[3][4] = {};  // rows of the affine inverse

    // Identity placement with nothing to add: the top level may point straight into the object's tree.
    bool direct() const { return identity && prim_offset == 0; }

    Vec3 point(const Vec3& p) const {
        return {world_to_object[0][0] * p.x + world_to_object[0][1] * p.y + world_to_object[0][2] * p.z + world_to_object[0][3],
                world_to_object[1][0] * p.x + world_to_object[1][1] * p.y + world_to_object[1][2] * p.z + world_to_object[1][3],
                world_to_object[2][0] * p.x + world_to_object[2][1] * p.y + world_to_object[2][2] * p.z + world_to_object[2][3]};
    }
    Vec3 vector(const Vec3& v) const {
        return {world_to_object[0][0] * v.x + world_to_object[0][1] * v.y + world_to_object[0][2] * v.z,
                world_to_object[1][0] * v.x + world_to_object[1][1] * v.y + world_to_object[1][2] * v.z,
                world_to_object[2][0] * v.x + world_to_object[2][1] * v.y + world_to_object[2][2] * v.z};
    }
};

// An object's tree inside TwoLevelBvh::pool.
struct ObjectTree {
    uint32_t root = 0;       // its root node in pool.nodes
    uint32_t triangles = 0;
    uint32_t prim_base = 0;  // added to the object's triangle ids in its leaves: its first identity placement's offset
    BBox bounds;             // in object space
    PlaneFrame frame;        // its planes': at the world origin when placed as it is anywhere, else at its centre
};

// A top-level leaf entry: a node (count 0) or leaf (count > 0) of an instance's object tree, as WideNode names
// its children, so traversal can enter the object tree there with the instance's ray.
struct TopLevelRef {
    uint32_t instance;
    uint32_t child, count;
};

// Every object tree and the top level share one node array and one leaf array, object trees first. A top-level
// child is one of: a top-level node; an object node or object leaf, reached with the world ray as any child is
// (a BRef of a direct() placement: sec. 5.5, the structure a plain BVH traversal walks); a leaf of the top level's
// own, holding triangles of opened object leaves in world space with scene-wide ids; or, flagged by
// kInstanceEntries in its count, a run of TopLevelRefs in `entries` that need the instance's ray.
template <int N>
struct TwoLevelBvh {
    static constexpr int kWidth = N;
    static constexpr uint32_t kInstanceEntries = 0x80000000u;
    WideBvh<N> pool;  // pool.frame, at the world origin: the top level's and the directly reached object trees'.
    uint32_t root = 0;          // the top level's root in pool.nodes
    uint32_t object_nodes = 0;  // pool.nodes before this index are object trees'
    uint32_t object_leaves = 0;  // pool.leaves likewise; after them, the top level's leaves of opened triangles
    std::vector<ObjectTree> objects;
    std::vector<PlacedObject> instances;
    std::vector<glm::mat4> to_world;  // per instance, for metrics (traversal only needs the inverse)
    std::vector<TopLevelRef> entries;
    uint32_t brefs = 0;  // the BRefs in the top level's leaves
    BBox bounds;

    uint32_t top_level_nodes() const { return uint32_t(pool.nodes.size()) - object_nodes; }
    uint64_t bytes() const;  // pool, entries, instances
};

struct TwoLevelTimes {
    double objects_ms = 0;    // every object BVH, built in parallel
    double top_level_ms = 0;  // BRef setup, top-level build and its collapse
};

// Builds every object tree (in parallel across objects) and the top level. Deterministic for any thread count.
template <int N>
TwoLevelBvh<N> build_two_level(const TwoLevelInput& input, const TwoLevelSettings& settings, TwoLevelTimes* times = nullptr);

// Rebuilds only the top level over the existing object trees (instances may have moved).
template <int N>
void build_top_level(TwoLevelBvh<N>& bvh, const std::vector<TwoLevelInstance>& instances, const TwoLevelSettings& settings);

// The same over the input's instances, skipping those of empty objects as build_two_level does; times only
// the top level. All a rigid move of an instance needs: its object tree stays valid (sec. 6.3, Table 3).
template <int N>
void rebuild_top_level(TwoLevelBvh<N>& bvh, const TwoLevelInput& input, const TwoLevelSettings& settings,
                       TwoLevelTimes* times = nullptr);

// Eq. 1 over the whole two-level structure as traversal sees it: top-level nodes, then for each top-level
// leaf the object subtree below its entry, every box in world space (conservatively transformed).
template <int N>
double sah_cost(const TwoLevelBvh<N>& bvh, SahCosts costs = {});

// The box of `box` transformed by `m`, rounded outwards so that it contains every transformed point.
BBox transform_bounds(const glm::mat4& m, const BBox& box);

}  // namespace canopy
