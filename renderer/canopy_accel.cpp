#include "accel/builder.h"
#include "kernels/traverse.h"
#include "renderer/accelerator.h"

#include <stdexcept>

namespace canopy {
namespace {

template <int N, bool Robust>
struct CanopyTracer {
    const WideBvh<N>& bvh;
    bool closest(const Ray& ray, Hit& hit) const { return closest_hit<Robust>(bvh, ray, hit); }
};

class CanopyAccelerator final : public Accelerator {
public:
    CanopyAccelerator(const FlatScene& scene, const CanopyOptions& options)
        : scene_(scene), options_(options), builder_(find_builder(options.builder)) {
        if (options.kernel != "bvh2")
            throw std::invalid_argument("unknown kernel '" + options.kernel + "' (known: bvh2)");
    }

    std::string library() const override { return "canopy"; }
    std::string builder() const override { return builder_.name; }
    std::string kernel() const override { return options_.kernel; }
    std::string quality() const override { return ""; }

    void prepare() override { refs_ = make_prim_refs(scene_.triangles); }

    void build() override {
        binary_ = builder_.build(BuildInput{scene_.triangles, std::move(refs_)}, settings_);
        wide_ = collapse<2>(binary_, scene_.triangles);
    }

    uint64_t render(const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame, Image& image,
                    const std::function<void(float)>& on_tile) const override {
        if (options_.robust) return render_frame(CanopyTracer<2, true>{wide_}, scene, camera, frame, image, on_tile);
        return render_frame(CanopyTracer<2, false>{wide_}, scene, camera, frame, image, on_tile);
    }

    Hit trace(const Ray& ray) const override {
        Hit hit;
        if (options_.robust) closest_hit<true>(wide_, ray, hit);
        else closest_hit<false>(wide_, ray, hit);
        return hit;
    }

    AcceleratorReport report() const override {
        const TreeStats stats = tree_stats(binary_, scene_.triangles.size());
        return {sah_cost(binary_, SahCosts{}), stats.nodes, stats.leaves, stats.depth, wide_.bytes(),
                stats.refs_per_triangle};
    }

private:
    const FlatScene& scene_;
    CanopyOptions options_;
    const BuilderEntry& builder_;
    BuildSettings settings_;
    std::vector<PrimRef> refs_;
    Bvh binary_;
    WideBvh<2> wide_;
};

}  // namespace

std::unique_ptr<Accelerator> make_canopy_accelerator(const FlatScene& scene, const CanopyOptions& options) {
    return std::make_unique<CanopyAccelerator>(scene, options);
}

}  // namespace canopy
