// The kd-tree as an accelerator (builder "kdtree"): accel/kdtree.h builds it, kernels/traverse_kd.h traces it, and
// frames run the same path tracer template as the BVHs' over a kd tracer type.
#include "accel/kdtree.h"
#include "kernels/dispatch.h"
#include "kernels/traverse_kd.h"
#include "renderer/accelerator.h"
#include "renderer/wavefront.h"

#include <tbb/enumerable_thread_specific.h>

#include <stdexcept>

namespace canopy {
namespace {

template <class TriangleTest>
struct KdTracer {
    const KdTree& tree;
    bool closest(const Ray& ray, Hit& hit) const { return traverse_kd<Query::Closest, TriangleTest>(tree, ray, hit); }
};

template <class TriangleTest>
struct KdCountingTracer {
    const KdTree& tree;
    tbb::enumerable_thread_specific<TraversalCounts>& counts;
    bool closest(const Ray& ray, Hit& hit) const {
        return traverse_kd<Query::Closest, TriangleTest>(tree, ray, hit, counts.local());
    }
};

// The stream tracer's batches, answered ray by ray: the kd kernel has no packet form, so a batch needs no scratch.
struct NoScratch {
    size_t bytes() const { return 0; }
};

template <Query Q, class TriangleTest>
void trace_rays(const KdTree& tree, std::span<const Ray> rays, std::span<Hit> hits) {
    for (size_t i = 0; i < rays.size(); ++i) traverse_kd<Q, TriangleTest>(tree, rays[i], hits[i]);
}

template <class TriangleTest>
struct KdBatchTracer {
    using Scratch = NoScratch;
    const KdTree& tree;
    void closest(std::span<const Ray> rays, std::span<Hit> hits, Scratch&) const {
        trace_rays<Query::Closest, TriangleTest>(tree, rays, hits);
    }
};

class KdAccelerator final : public Accelerator {
    // Calls f.template operator()<TriangleTest>() with the options' intersector: the kernel's one choice.
    template <class F>
    auto with_test(F&& f) const {
        return options_.watertight ? f.template operator()<WatertightRay>() : f.template operator()<MollerTrumboreRay>();
    }

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

    uint64_t render(const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame, Image& image,
                    const std::function<void(float)>& on_tile) const override {
        return with_test([&]<class Test>() {
            if (scene.settings.tracer == TracerKind::Stream)
                return render_frame_stream(KdBatchTracer<Test>{tree_}, scene, camera, frame, image, on_tile);
            return render_frame(KdTracer<Test>{tree_}, scene, camera, frame, image, on_tile);
        });
    }

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
        return with_test([&]<class Test>() {
            Hit hit;
            traverse_kd<Query::Closest, Test>(tree_, ray, hit);
            return hit;
        });
    }

    TraversalCounts count(const Ray& ray) const override {
        return with_test([&]<class Test>() {
            TraversalCounts counts;
            Hit hit;
            traverse_kd<Query::Closest, Test>(tree_, ray, hit, counts);
            return counts;
        });
    }

    std::pair<TraversalCounts, uint64_t> count_frame(const ShadingScene& scene, const PinholeCamera& camera,
                                                     uint32_t frame) const override {
        tbb::enumerable_thread_specific<TraversalCounts> counts;
        Image unused(scene.settings.width, scene.settings.height);
        const uint64_t rays = with_test([&]<class Test>() {
            return render_frame(KdCountingTracer<Test>{tree_, counts}, scene, camera, frame, unused);
        });
        return {counts.combine([](TraversalCounts a, const TraversalCounts& b) { return a += b; }), rays};
    }

    void trace_batch(Query query, std::span<const Ray> rays, std::span<Hit> hits) const override {
        with_test([&]<class Test>() {
            if (query == Query::Any) trace_rays<Query::Any, Test>(tree_, rays, hits);
            else trace_rays<Query::Closest, Test>(tree_, rays, hits);
        });
    }

private:
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
