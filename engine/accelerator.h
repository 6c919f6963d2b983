#pragma once
// An accelerator as the renderer, the benchmark and the library see it: built from a flat scene (or its objects
// and instances), then queried. Its bound_kernel() binds the built tree to its compiled traversal, so that a
// caller's loop over rays is instantiated once per kernel and dispatched once per frame or batch, not per ray.
#include "engine/auto_builder.h"
#include "kernels/dispatch.h"

#include <memory>
#include <optional>
#include <string>

namespace canopy {

struct AcceleratorReport {
    std::optional<double> sah, epo;            // eq. 1 and eq. 3 of the quality-metrics paper, of the binary tree
    std::optional<double> layout_sah, layout_epo;  // the same of the traversal layout (wide trees for bvh4 and bvh8)
    std::optional<uint64_t> nodes, leaves, depth, bytes;
    std::optional<double> refs_per_tri;
    std::optional<double> split_ms;           // the split pass's share of the build (split builders)
    std::optional<double> ref_capacity_per_tri;  // PrimRef slots allocated per triangle (1.39: 39% extra)
    std::optional<double> objects_ms, top_level_ms;  // two-level builds: the object trees, the top level alone
    std::optional<uint64_t> brefs;                   // two-level builds: top-level leaf references
};

// Dynamic-in-static scenes (Benthin et al. 2017, sec. 6.3): one placement, an instance of
// two_level_input(scene), moved rigidly to `to_world`; the flat scene's triangles [first_triangle,
// first_triangle + triangle_count) already show it there.
struct PlacementMove {
    uint32_t placement = 0;
    glm::mat4 to_world{1.0f};
    uint32_t first_triangle = 0, triangle_count = 0;
};

class Accelerator {
public:
    virtual ~Accelerator() = default;
    virtual std::string library() const = 0;  // "canopy" or "embree"
    virtual std::string builder() const = 0;  // canopy builder name, or null-like "" for embree
    virtual std::string kernel() const = 0;  // canopy: width and modes, e.g. "bvh8" or "bvh8 fast mt"
    virtual std::string quality() const = 0;  // embree build quality, "" for canopy
    // `--builder auto`: what it chose (builder, with "two-level/" in front when it chose that) and why.
    virtual std::string chosen() const { return ""; }
    virtual std::string reason() const { return ""; }
    // `--builder auto`: the last build's calibration (every candidate's predicted or measured costs); null otherwise.
    virtual const AutoChoice* auto_choice() const { return nullptr; }
    virtual int frames_planned() const { return 0; }

    // Untimed preparation for one build (canopy: PrimRef generation), then the timed build.
    virtual void prepare() = 0;
    virtual void build() = 0;
    // After a build: rebuilds what the move invalidates (timed by the caller). A flat BVH knows no placements
    // and is built again over all world triangles, PrimRefs included; a two-level one rebuilds its top level
    // only, as a rigid move leaves every object tree valid.
    virtual void move(const PlacementMove& move) = 0;
    // The built tree's kernel (kernels/dispatch.h's with_kernel calls code with its type); monostate for an
    // accelerator of another library, whose frames go through its own calls.
    virtual AnyKernel bound_kernel() const { return {}; }
    // Tree statistics and metrics after a build; with_epo = false skips EPO, whose exact clipping takes minutes
    // on millions of triangles.
    virtual AcceleratorReport report(bool with_epo) const = 0;
    // One closest-hit query, for tests and tools; frames go through render().
    virtual Hit trace(const Ray& ray) const = 0;
    // The same query through the counting variant of the kernel: what the ray visited. Throws
    // std::invalid_argument for an accelerator that cannot count (Embree).
    virtual TraversalCounts count(const Ray& ray) const = 0;
    // Closest hits (Query::Closest) or any hits (Query::Any) of a batch, each the single-ray query's answer,
    // through the batch kernel's packets on the calling thread. Throws std::invalid_argument for an accelerator
    // without one (Embree, whose batches only the stream tracer drives).
    virtual void trace_batch(Query query, std::span<const Ray> rays, std::span<Hit> hits) const = 0;
};

struct CanopyOptions {
    std::string builder = "binned";  // a builder spec with its parameters, "sbvh:alpha=1e-5" (accel/builder.h)
    std::string start;  // optimisers: the builder of the start tree ("" for the optimiser's default)
    std::string kernel = "auto";  // bvh2, bvh4, bvh8, or auto: the widest this build and CPU run
    bool robust = true;      // robust traversal (Ize 2013); false is the measured fast mode
    bool watertight = true;  // watertight intersection (Woop et al. 2013); false: Möller–Trumbore, the fast mode
    // flat: one BVH over world triangles; two-level: object BVHs (built by `builder`) under a top level over
    // instances; rebraid: that top level opening object BVHs where they overlap (Benthin et al. 2017).
    std::string toplevel = "flat";
    // builder "auto" plans for this many frames (time to image = build + frames x frame) of the caller's
    // workload, a sample of which its calibration traces through each candidate (null: random rays in the scene).
    int frames_planned = 16;
    std::shared_ptr<WorkloadSample> auto_sample;
    // How bvh4 and bvh8 are made; unset, the builder's own (collapse_of): lbvh's flat wide trees come straight
    // from its Morton codes (CollapseMethod::Direct), every other tree from the optimal collapse of its binary tree.
    std::optional<CollapseMethod> collapse;
    NodeLayout layout = NodeLayout::Standard;           // bvh8 nodes as floats, or quantised to bytes
    // Flat trees: the layout's nodes shuffled in memory with this seed after the build (permute_nodes, untimed
    // study experiment); the tree and every answer stay the same.
    std::optional<uint64_t> permute_nodes;
    // rebraid: open BRefs wider than this share of their segment's largest extent (Benthin et al. 2017, sec. 4.2).
    float rebraid_threshold = TwoLevelSettings{}.open_extent;
};

// Throws std::invalid_argument for an unknown builder or kernel, or a two-level top level (it needs the scene).
std::unique_ptr<Accelerator> make_canopy_accelerator(const FlatScene& scene, const CanopyOptions& options);
// The collapse a tree of these options is made with: the one asked for, else the builder's own. lbvh is the
// builder for the fastest build, and its direct wide tree builds faster than its binary tree and that tree's optimal
// collapse for frames a little longer (docs/results.md#lbvhs-direct-wide-tree).
CollapseMethod collapse_of(const CanopyOptions& options);
// Throw std::invalid_argument for a collapse (direct: lbvh, bvh4 or bvh8, flat) or a node layout (compressed: a
// named BVH builder, bvh8, flat) the options' builder, kernel or top level cannot take; check_layout_options does
// both, as both make_canopy_accelerator overloads do.
void check_collapse_options(const CanopyOptions& options);
void check_node_layout_options(const CanopyOptions& options);
void check_layout_options(const CanopyOptions& options);
// Any top level: `flat` must be flatten(scene).
std::unique_ptr<Accelerator> make_canopy_accelerator(const Scene& scene, const FlatScene& flat, const CanopyOptions& options);
// Builder "kdtree" (engine/kd_accelerator.cpp), which make_canopy_accelerator routes there: kernel "kd", flat top
// level only (std::invalid_argument otherwise).
std::unique_ptr<Accelerator> make_kd_accelerator(const FlatScene& scene, const CanopyOptions& options);

// Objects (OBJ groups) in object space, and a two-level instance per (scene instance, object), with triangle ids
// numbered as flatten() numbers them, so hits index the flat scene's triangles.
TwoLevelInput two_level_input(const Scene& scene);

}  // namespace canopy
