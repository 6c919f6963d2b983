// The kd-tree as an accelerator (builder "kdtree"): accel/kdtree.h builds it, kernels/traverse_kd.h traces it, and
// frames run the same path tracer template as the BVHs' over its kernel (kernels/kernel.h).
#include "accel/kdtree.h"
#include "kernels/dispatch.h"
#include "kernels/traverse_kd.h"
#include "engine/accelerator.h"

#include <tbb/enumerable_thread_specific.h>

#include <stdexcept>

namespace canopy {
namespace {

class KdAccelerator final : public Accelerator {
public:
    KdAccelerator(const FlatScene& scene, const CanopyOptions& options) : scene_(scene), options_(options) {
        if (options.toplevel != "flat")
            throw std::invalid_argument("builder '" + options.builder + "' builds one kd-tree over world triangles: --toplevel " +
                                        options.toplevel + " needs object BVHs (use flat, or a BVH builder)");
        if (!options.start.empty())
            throw std::invalid_argument("--start " + options.start + ": builder '" + options.builder +
                                        "' is not an optimiser and takes no start tree");
        if (options.permute_nodes)
            throw std::invalid_argument("builder '" + options.builder + "': permuted nodes are an experiment on wide BVH layouts");
        kernel_width(options.kernel);  // an unknown kernel name fails here as for the BVHs; the kd kernel has no width
    }

    std::string library() const override { return "canopy"; }
    std::string builder() const override { return kKdTreeName; }
    std::string kernel() const override { return options_.watertight ? "kd" : "kd mt"; }
    std::string quality() const override { return ""; }

    // Frees the previous build, untimed, as the BVH rows do.
    void prepare() override { tree_ = KdTree{}; }
    void build() override { tree_ = build_kdtree(scene_.triangles, settings_); }
    void move(const PlacementMove&) override {
        prepare();
        build();
    }

    AnyKernel bound_kernel() const override { return make_kernel(tree_, {true, options_.watertight}); }

    AcceleratorReport report(bool) const override {
        const KdStats stats = kd_stats(tree_, scene_.triangles.size());
        AcceleratorReport r;
        r.sah = kd_sah_cost(tree_);  // EPO is defined for BVHs only: left empty
        r.nodes = stats.nodes, r.leaves = stats.leaves, r.depth = stats.depth;
        r.bytes = tree_.bytes();
        r.refs_per_tri = stats.refs_per_triangle;
        return r;
    }

    Hit trace(const Ray& ray) const override {
        Hit hit;
        with_test([&](const auto& kernel) { kernel.closest(ray, hit); });
        return hit;
    }

    TraversalCounts count(const Ray& ray) const override {
        TraversalCounts counts;
        Hit hit;
        with_test([&](const auto& kernel) { kernel.query(ray, hit, counts); });
        return counts;
    }

    void trace_batch(Query query, std::span<const Ray> rays, std::span<Hit> hits) const override {
        with_test([&]<class Kernel>(const Kernel& kernel) {
            NoScratch none;
            if (query == Query::Any) kernel.template batch<Query::Any>(rays, hits, none, BatchTraversal::Single);
            else kernel.template batch<Query::Closest>(rays, hits, none, BatchTraversal::Single);
        });
    }

private:
    // Calls f(kernel) with the tree's kernel in the options' intersector.
    template <class F>
    void with_test(F&& f) const {
        if (options_.watertight) f(KdKernel<WatertightRay>{tree_});
        else f(KdKernel<MollerTrumboreRay>{tree_});
    }

    const FlatScene& scene_;
    CanopyOptions options_;
    KdSettings settings_;
    KdTree tree_;
};

}  // namespace

std::unique_ptr<Accelerator> make_kd_accelerator(const FlatScene& scene, const CanopyOptions& options) {
    return std::make_unique<KdAccelerator>(scene, options);
}

}  // namespace canopy
