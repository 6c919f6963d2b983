#include "accel/builder.h"
#include "accel/metrics.h"
#include "kernels/dispatch.h"
#include "kernels/traverse.h"
#include "renderer/accelerator.h"

#include <variant>

namespace canopy {
namespace {

template <int N, bool Robust, class TriangleTest>
struct CanopyTracer {
    const WideBvh<N>& bvh;
    bool closest(const Ray& ray, Hit& hit) const { return closest_hit<Robust, TriangleTest>(bvh, ray, hit); }
};

// Calls f(robust, triangle test) with both as types, so each combination is its own compiled kernel.
template <class F>
auto with_modes(const CanopyOptions& o, F&& f) {
    using Watertight = std::type_identity<WatertightRay>;
    using Moller = std::type_identity<MollerTrumboreRay>;
    if (o.robust) return o.watertight ? f(std::true_type{}, Watertight{}) : f(std::true_type{}, Moller{});
    return o.watertight ? f(std::false_type{}, Watertight{}) : f(std::false_type{}, Moller{});
}

using AnyLayout = std::variant<WideBvh<2>, WideBvh<4>, WideBvh<8>>;

template <int N>
void collapse_into(AnyLayout& layout, const Bvh& bvh, std::span<const Triangle> triangles) {
    if constexpr (kernel_compiled(N)) layout = collapse<N>(bvh, triangles);
}

class CanopyAccelerator final : public Accelerator {
    // Calls f.template operator()<N, Robust, TriangleTest>(layout) with the built layout and the options' modes
    // as compile-time arguments: the one dispatch every query goes through, once per frame or per call. Widths
    // this build did not compile never get here (kernel_width rejects them), so they answer a default value.
    template <class F>
    auto with_kernel(F&& f) const {
        using Result = decltype(f.template operator()<2, true, WatertightRay>(std::get<0>(layout_)));
        return std::visit([&](const auto& bvh) -> Result {
            constexpr int N = std::decay_t<decltype(bvh)>::kWidth;
            if constexpr (kernel_compiled(N)) {
                return with_modes(options_, [&](auto robust, auto test) {
                    return f.template operator()<N, decltype(robust)::value, typename decltype(test)::type>(bvh);
                });
            } else {
                return Result{};
            }
        }, layout_);
    }

public:
    CanopyAccelerator(const FlatScene& scene, const CanopyOptions& options)
        : scene_(scene), options_(options), builder_(find_builder(options.builder)), width_(kernel_width(options.kernel)) {
        if (width_ > 2) settings_.leaf_block = 4;  // the SIMD kernels test leaf triangles 4 at a time
        if (!options.start.empty()) {
            if (!builder_.default_start)
                throw std::invalid_argument("--start " + options.start + ": builder '" + builder_.name +
                                            "' is not an optimiser and takes no start tree");
            find_builder(options.start);
            settings_.start = options.start;
        }
    }

    std::string library() const override { return "canopy"; }
    std::string builder() const override {
        return builder_.default_start ? builder_.name + "<" + (settings_.start.empty() ? builder_.default_start : settings_.start)
                                      : builder_.name;
    }
    std::string kernel() const override {
        return kernel_name(width_) + (options_.robust ? "" : " fast") + (options_.watertight ? "" : " mt");
    }
    std::string quality() const override { return ""; }

    void prepare() override { refs_ = make_prim_refs(scene_.triangles); }

    // The timed build: the builder's binary BVH and its collapse into the kernel's layout.
    void build() override {
        binary_ = builder_.build(BuildInput{scene_.triangles, std::move(refs_)}, settings_);
        switch (width_) {
            case 2: collapse_into<2>(layout_, binary_, scene_.triangles); break;
            case 4: collapse_into<4>(layout_, binary_, scene_.triangles); break;
            default: collapse_into<8>(layout_, binary_, scene_.triangles); break;
        }
    }

    uint64_t render(const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame, Image& image,
                    const std::function<void(float)>& on_tile) const override {
        return with_kernel([&]<int N, bool Robust, class Test>(const WideBvh<N>& bvh) {
            return render_frame(CanopyTracer<N, Robust, Test>{bvh}, scene, camera, frame, image, on_tile);
        });
    }

    Hit trace(const Ray& ray) const override {
        return with_kernel([&]<int N, bool Robust, class Test>(const WideBvh<N>& bvh) {
            Hit hit;
            closest_hit<Robust, Test>(bvh, ray, hit);
            return hit;
        });
    }

    TraversalCounts count(const Ray& ray) const override {
        return with_kernel([&]<int N, bool Robust, class Test>(const WideBvh<N>& bvh) {
            TraversalCounts counts;
            Hit hit;
            traverse<Query::Closest, Robust, Test>(bvh, ray, hit, counts);
            return counts;
        });
    }

    AcceleratorReport report() const override {
        const TreeStats stats = tree_stats(binary_, scene_.triangles.size());
        AcceleratorReport r{sah_cost(binary_, SahCosts{}), epo_cost(binary_, scene_.triangles), {}, {}, stats.nodes,
                            stats.leaves, stats.depth, {}, stats.refs_per_triangle};
        if (binary_.split.reference_capacity) {
            r.split_ms = binary_.split.split_ms;
            r.ref_capacity_per_tri = double(binary_.split.reference_capacity) / double(scene_.triangles.size());
        }
        std::visit([&](const auto& bvh) {
            r.bytes = bvh.bytes();
            r.layout_sah = sah_cost(bvh);
            r.layout_epo = epo_cost(bvh, scene_.triangles);
        }, layout_);
        return r;
    }

private:
    const FlatScene& scene_;
    CanopyOptions options_;
    const BuilderEntry& builder_;
    const int width_;
    BuildSettings settings_;
    std::vector<PrimRef> refs_;
    Bvh binary_;
    AnyLayout layout_;
};

}  // namespace

std::unique_ptr<Accelerator> make_canopy_accelerator(const FlatScene& scene, const CanopyOptions& options) {
    return std::make_unique<CanopyAccelerator>(scene, options);
}

}  // namespace canopy
