#include "accel/builder.h"
#include "accel/builders/lbvh_direct.h"
#include "accel/kdtree.h"
#include "accel/metrics.h"
#include "kernels/dispatch.h"
#include "kernels/traverse.h"
#include "kernels/traverse_stream.h"
#include "kernels/traverse_two_level.h"
#include "engine/accelerator.h"
#include "engine/random_ray_sample.h"
#include "engine/auto_builder.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <type_traits>
#include <variant>

namespace canopy {
namespace {

KernelModes modes_of(const CanopyOptions& o) { return {o.robust, o.watertight}; }

template <int N>
void collapse_into(AnyLayout& layout, const Bvh& bvh, std::span<const Triangle> triangles, CollapseMethod method) {
    if constexpr (kernel_compiled(N)) layout = collapse<N>(bvh, triangles, method);
}

template <int N>
void build_wide_lbvh_into(AnyLayout& layout, BuildInput&& input) {
    if constexpr (kernel_compiled(N) && N > 2) layout = build_wide_lbvh<N>(std::move(input));
}

template <int N>
void build_two_level_into(AnyLayout& layout, const TwoLevelInput& input, const TwoLevelSettings& settings,
                          TwoLevelTimes& times) {
    if constexpr (kernel_compiled(N)) layout = build_two_level<N>(input, settings, &times);
}

template <int N>
void rebuild_top_level_of(AnyLayout& layout, const TwoLevelInput& input, const TwoLevelSettings& settings,
                          TwoLevelTimes& times) {
    if constexpr (kernel_compiled(N)) rebuild_top_level(std::get<TwoLevelBvh<N>>(layout), input, settings, &times);
}

template <class Layout>
constexpr bool is_two_level = requires(const Layout& l) { l.instances; };

TopLevel parse_top_level(const std::string& name) {
    if (name == "two-level") return TopLevel::TwoLevel;
    if (name == "rebraid") return TopLevel::Rebraid;
    throw std::invalid_argument("unknown top level '" + name + "' (known: flat, two-level, rebraid)");
}

class CanopyAccelerator final : public Accelerator {
    // Calls f(kernel) with the built layout's kernel in the options' modes; `none` answers for widths this build
    // did not compile, which kernel_width rejects before they get here.
    template <class F>
    auto with_built_kernel(F&& f) const {
        using Result = decltype(f(std::declval<BvhKernel<WideBvh<2>, true, WatertightRay>>()));
        return with_kernel(bound_kernel(), std::forward<F>(f), []() -> Result {
            if constexpr (!std::is_void_v<Result>) return Result{};
        });
    }

public:
    // `objects` is the scene whose objects and instances a two-level top level is built over; null for flat.
    CanopyAccelerator(const Scene* objects, const FlatScene& scene, const CanopyOptions& options)
        : scene_(scene), options_(options), spec_(parse_builder_spec(options.builder)),
          builder_(find_builder(spec_.name)), width_(kernel_width(options.kernel)),
          collapse_(collapse_of(options)) {
        // SAH charges a leaf one test per 4 triangles for the SIMD kernels although they test 8 at once, and allows
        // leaves of two blocks where SAH prefers them to a split: both traced and built faster than leaves charged
        // per 8 or capped at 8 (docs/results.md#leaf-sizes-of-the-simd-kernels).
        if (width_ > 2) settings_.leaf_block = 4, settings_.max_leaf_size = 16;
        settings_.params = spec_.params;
        if (!options.start.empty()) {
            if (!builder_.default_start)
                throw std::invalid_argument("--start " + options.start + ": builder '" + builder_.name +
                                            "' is not an optimiser and takes no start tree");
            find_builder(parse_builder_spec(options.start).name);
            settings_.start = options.start;
        }
        if (options.toplevel != "flat") {
            if (options.permute_nodes) throw std::invalid_argument("permuted nodes: flat trees only, not top level '" + options.toplevel + "'");
            two_level_settings_.top = parse_top_level(options.toplevel);
            if (!objects) throw std::invalid_argument("top level '" + options.toplevel + "' needs the scene's objects");
            two_level_settings_.blas_builder = spec_.name;
            two_level_settings_.blas = settings_;
            two_level_settings_.collapse = collapse_;
            if (!(options.rebraid_threshold >= 0.0f && options.rebraid_threshold <= 1.0f))
                throw std::invalid_argument("rebraid threshold " + std::to_string(options.rebraid_threshold) +
                                            ": a share of the segment's extent, from 0 to 1");
            two_level_settings_.open_extent = options.rebraid_threshold;
            two_level_input_ = two_level_input(*objects);
        }
    }

    std::string library() const override { return "canopy"; }
    std::string builder() const override {
        const std::string name = builder_.default_start
                                     ? builder_.name + "<" + (settings_.start.empty() ? builder_.default_start : settings_.start)
                                     : spec_.text();
        if (!two_level_input_) return name;
        return top_level_name() + "/" + name;
    }
    std::string kernel() const override {
        return kernel_name(width_) + (options_.layout == NodeLayout::Compressed ? " compressed" : "") + collapse_suffix() +
               (options_.robust ? "" : " fast") + (options_.watertight ? "" : " mt") + (options_.permute_nodes ? " permuted" : "");
    }
    std::string quality() const override { return ""; }
    // " greedy" or " direct" for a wide tree not made by the optimal collapse (at width 2 all collapses agree).
    std::string collapse_suffix() const {
        if (width_ == 2) return "";
        switch (collapse_) {
            case CollapseMethod::Greedy: return " greedy";
            case CollapseMethod::Direct: return " direct";
            default: return "";
        }
    }
    // "rebraid@5%" for a re-braided top level with another than the default opening threshold.
    std::string top_level_name() const {
        if (options_.toplevel != "rebraid" || options_.rebraid_threshold == TwoLevelSettings{}.open_extent) return options_.toplevel;
        char percent[32];
        std::snprintf(percent, sizeof percent, "@%g%%", 100.0 * options_.rebraid_threshold);
        return options_.toplevel + percent;
    }

    void prepare() override {
        release();
        if (!two_level_input_) refs_ = make_prim_refs(scene_.triangles);
    }
    // prepare() with the scene's PrimRefs made by the caller (make_prim_refs of this scene's triangles); flat only.
    void prepare(std::vector<PrimRef>&& refs) {
        if (two_level_input_) throw std::logic_error("PrimRefs handed to a two-level build");
        release();
        refs_ = std::move(refs);
    }

    // Frees the previous build. prepare() does it untimed, as the Embree rows release their previous scene in
    // theirs: freeing tens of MB is no part of building.
    void release() {
        layout_ = AnyLayout{};
        binary_ = Bvh{};
    }

    // The timed build: the builder's binary BVH and its collapse into the kernel's layout, or lbvh's direct wide
    // tree; for a two-level top level, every object's tree and the top level (object PrimRefs are made inside, and
    // timed).
    void build() override {
        if (two_level_input_) {
            TwoLevelTimes times;
            switch (width_) {
                case 2: build_two_level_into<2>(layout_, *two_level_input_, two_level_settings_, times); break;
                case 4: build_two_level_into<4>(layout_, *two_level_input_, two_level_settings_, times); break;
                default: build_two_level_into<8>(layout_, *two_level_input_, two_level_settings_, times); break;
            }
            // Each part's fastest build, as the bench reports the fastest whole build: a top level of tens of
            // microseconds timed once is mostly noise.
            if (!two_level_built_ || times.objects_ms < two_level_times_.objects_ms) two_level_times_.objects_ms = times.objects_ms;
            if (!two_level_built_ || times.top_level_ms < two_level_times_.top_level_ms) two_level_times_.top_level_ms = times.top_level_ms;
            two_level_built_ = true;
            return;
        }
        if (collapse_ == CollapseMethod::Direct) {  // no binary tree (check_layout_options: lbvh, bvh4 or bvh8)
            if (width_ == 4) build_wide_lbvh_into<4>(layout_, BuildInput{scene_.triangles, std::move(refs_)});
            else build_wide_lbvh_into<8>(layout_, BuildInput{scene_.triangles, std::move(refs_)});
        } else {
            build_binary_and_collapse();
        }
        if (options_.permute_nodes)
            std::visit([&]<class Layout>(Layout& bvh) {
                if constexpr (requires { permute_nodes(bvh, uint64_t{}); }) permute_nodes(bvh, *options_.permute_nodes);
            }, layout_);
        if constexpr (kernel_compiled(8))
            if (options_.layout == NodeLayout::Compressed) layout_ = compress(std::get<WideBvh<8>>(std::move(layout_)));
    }

    // The sibling overlap of the binary tree (accel/metrics.h); negative where there is none (two-level, direct).
    double sibling_overlap() const { return binary_.nodes.empty() ? -1.0 : canopy::sibling_overlap(binary_); }

    // The builder's binary BVH and its collapse into the kernel's layout.
    void build_binary_and_collapse() {
        binary_ = builder_.build(BuildInput{scene_.triangles, std::move(refs_)}, settings_);
        switch (width_) {
            case 2: collapse_into<2>(layout_, binary_, scene_.triangles, collapse_); break;
            case 4: collapse_into<4>(layout_, binary_, scene_.triangles, collapse_); break;
            default: collapse_into<8>(layout_, binary_, scene_.triangles, collapse_); break;
        }
    }

    // Model of a rigid move: the placement's transform changes, its object tree does not (sec. 6.3 rebuilds
    // the dynamic objects too, because the paper's robot deforms).
    void move(const PlacementMove& move) override {
        if (!two_level_input_) {
            prepare();
            return build();
        }
        two_level_input_->instances.at(move.placement).to_world = move.to_world;
        two_level_times_.objects_ms = 0;
        switch (width_) {
            case 2: rebuild_top_level_of<2>(layout_, *two_level_input_, two_level_settings_, two_level_times_); break;
            case 4: rebuild_top_level_of<4>(layout_, *two_level_input_, two_level_settings_, two_level_times_); break;
            default: rebuild_top_level_of<8>(layout_, *two_level_input_, two_level_settings_, two_level_times_); break;
        }
    }

    AnyKernel bound_kernel() const override { return make_kernel(layout_, modes_of(options_)); }

    Hit trace(const Ray& ray) const override {
        return with_built_kernel([&](const auto& kernel) {
            Hit hit;
            kernel.closest(ray, hit);
            return hit;
        });
    }

    TraversalCounts count(const Ray& ray) const override {
        return with_built_kernel([&](const auto& kernel) {
            TraversalCounts counts;
            Hit hit;
            kernel.query(ray, hit, counts);
            return counts;
        });
    }

    void trace_batch(Query query, std::span<const Ray> rays, std::span<Hit> hits) const override {
        with_built_kernel([&]<class Kernel>(const Kernel& kernel) {
            typename Kernel::Scratch unused;  // packets need none
            if (query == Query::Any) kernel.template batch<Query::Any>(rays, hits, unused, BatchTraversal::Packet);
            else kernel.template batch<Query::Closest>(rays, hits, unused, BatchTraversal::Packet);
        });
    }

    AcceleratorReport report(bool with_epo) const override {
        if (two_level_input_) return two_level_report();
        AcceleratorReport r;
        if (!binary_.nodes.empty()) {  // lbvh's direct wide tree has no binary tree to measure
            const TreeStats stats = tree_stats(binary_, scene_.triangles.size());
            r = {sah_cost(binary_, SahCosts{}), {}, {}, {}, stats.nodes, stats.leaves, stats.depth, {}, stats.refs_per_triangle};
            if (with_epo) r.epo = epo_cost(binary_, scene_.triangles);
        }
        if (binary_.split.reference_capacity) {
            r.split_ms = binary_.split.split_ms;
            r.ref_capacity_per_tri = double(binary_.split.reference_capacity) / double(scene_.triangles.size());
        }
        std::visit([&]<class Layout>(const Layout& bvh) {
            if constexpr (!is_two_level<Layout>) {
                r.bytes = bvh.bytes();
                // A compressed tree's metrics are those of its decoded boxes.
                const auto& boxes = [&]() -> decltype(auto) {
                    if constexpr (std::is_same_v<Layout, CompressedWideBvh<8>>) return decompress(bvh);
                    else return (bvh);
                }();
                r.layout_sah = sah_cost(boxes);
                if (with_epo) r.layout_epo = epo_cost(boxes, scene_.triangles);
            }
        }, layout_);
        return r;
    }

private:
    // SAH of the structure as traversal sees it (top level and object subtrees in world space); nodes are the
    // top level's, leaves its BRefs.
    AcceleratorReport two_level_report() const {
        AcceleratorReport r;
        r.objects_ms = two_level_times_.objects_ms;
        r.top_level_ms = two_level_times_.top_level_ms;
        std::visit([&]<class Layout>(const Layout& bvh) {
            if constexpr (is_two_level<Layout>) {
                r.layout_sah = sah_cost(bvh);
                r.bytes = bvh.bytes();
                r.nodes = bvh.top_level_nodes();
                r.brefs = r.leaves = bvh.brefs;
            }
        }, layout_);
        return r;
    }

    const FlatScene& scene_;
    CanopyOptions options_;
    const BuilderSpec spec_;
    const BuilderEntry& builder_;
    const int width_;
    const CollapseMethod collapse_;
    BuildSettings settings_;
    std::vector<PrimRef> refs_;
    Bvh binary_;
    AnyLayout layout_;
    std::optional<TwoLevelInput> two_level_input_;
    TwoLevelSettings two_level_settings_;
    TwoLevelTimes two_level_times_;  // the fastest builds' parts; after a move, that rebuild's
    bool two_level_built_ = false;
};

// `--builder auto`: each build computes the scene statistics and runs the calibration (engine/auto_builder.h),
// which builds candidates and traces the planned frame's sample pixels through them; the winner's tree is the one
// the calibration built. All of it is timed but the first flat candidate's PrimRefs, which prepare() makes untimed,
// as every other row's; the next candidates make theirs inside their timed builds.
class AutoAccelerator final : public Accelerator, private Calibration {
public:
    AutoAccelerator(const Scene& scene, const FlatScene& flat, const CanopyOptions& options)
        : scene_(scene), flat_(flat), options_(options),
          sample_(options.auto_sample ? options.auto_sample : random_ray_sample(flat)) {
        stride_ = sample_stride(options.frames_planned);
        // A sample of a few milliseconds times its tiles' dispatch as much as their paths; planning one frame, the
        // sample's own cost outweighs its precision.
        min_sample_ms_ = options.frames_planned > 1 ? 5.0 : 0.0;
    }

    // A sample's share of the frame grows with the frames planned, as its cost is paid once and its precision
    // decides between candidates whose frames are all paid: from one tile in 128 for one frame to one in 8 from
    // 256 frames.
    static uint32_t sample_stride(int frames) {
        return uint32_t(std::clamp(128.0 / std::sqrt(double(frames)), 8.0, 128.0));
    }

    std::string library() const override { return "canopy"; }
    std::string builder() const override { return "auto"; }
    std::string kernel() const override { return chosen_ ? chosen_->kernel() : kernel_name(kernel_width(options_.kernel)); }
    std::string quality() const override { return ""; }
    std::string chosen() const override { return chosen_ ? chosen_->builder() : ""; }
    std::string reason() const override { return choice_.reason; }
    const AutoChoice* auto_choice() const override { return chosen_ ? &choice_ : nullptr; }
    int frames_planned() const override { return options_.frames_planned; }

    // PrimRefs for the first flat candidate, none where auto builds two-level trees only (a flattened scene of tens
    // of millions of instanced triangles would hold them for nothing).
    void prepare() override {
        chosen_.reset();
        const bool flat = flat_candidates(flat_.triangles.size(), scene_size(scene_).triangles);
        refs_ = flat ? make_prim_refs(flat_.triangles) : std::vector<PrimRef>{};
    }

    void build() override {
        warmed_up_ = false;
        choice_ = choose_builder(scene_statistics(scene_, flat_, sample_->aspect()), options_.frames_planned,
                                 sample_->pixels(), *this);
        chosen_ = std::move(trees_.at(key(choice_.builder, choice_.toplevel)));
        trees_.clear();
    }

    void move(const PlacementMove& move) override {
        if (!chosen_) throw std::logic_error("auto accelerator moved before build()");
        chosen_->move(move);
    }

    AnyKernel bound_kernel() const override { return built().bound_kernel(); }
    Hit trace(const Ray& ray) const override { return built().trace(ray); }
    TraversalCounts count(const Ray& ray) const override { return built().count(ray); }
    void trace_batch(Query query, std::span<const Ray> rays, std::span<Hit> hits) const override {
        built().trace_batch(query, rays, hits);
    }
    AcceleratorReport report(bool with_epo) const override { return built().report(with_epo); }

private:
    static std::string key(const std::string& builder, const std::string& toplevel) { return toplevel + "/" + builder; }

    double build(const std::string& builder, const std::string& toplevel) override {
        CanopyOptions options = options_;
        options.builder = builder, options.toplevel = toplevel, options.start.clear();
        const auto start = std::chrono::steady_clock::now();
        auto tree = std::make_unique<CanopyAccelerator>(&scene_, flat_, options);
        if (toplevel == "flat" && !refs_.empty()) {
            tree->prepare(std::move(refs_));
            refs_.clear();
        } else {
            tree->prepare();
        }
        tree->build();
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        last_ = tree.get();
        trees_[key(builder, toplevel)] = std::move(tree);
        return ms;
    }

    SampleReading sample_frame() override {
        // An untimed warm-up first: through the first tree half a sample, as the first sample after waking the
        // threads is slower than the next ones through the same tree; through each later tree, one part in
        // kTreeWarmUpStride, which brings its nodes into the caches.
        const auto warm_up = std::chrono::steady_clock::now();
        sample_->trace(*last_, warmed_up_ ? kTreeWarmUpStride : stride_ * 2);
        warmed_up_ = true;
        for (uint32_t stride = stride_;;) {
            const auto start = std::chrono::steady_clock::now();
            sample_->trace(*last_, stride);
            const auto end = std::chrono::steady_clock::now();
            const double ms = std::chrono::duration<double, std::milli>(end - start).count();
            if (ms < min_sample_ms_ && stride > 1) {  // too short to time: more of it, as much as min_sample_ms_ needs
                stride = next_sample_stride(stride, ms, min_sample_ms_);
                continue;
            }
            const double share = sample_->share(stride);
            return {std::chrono::duration<double, std::milli>(end - warm_up).count(), ms, share > 0.0 ? ms / share : 0.0};
        }
    }

    TreeReading read_tree() override {
        const auto start = std::chrono::steady_clock::now();
        const double overlap = last_ ? last_->sibling_overlap() : -1.0;
        return {overlap, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count()};
    }
    void discard(const std::string& builder, const std::string& toplevel) override { trees_.erase(key(builder, toplevel)); }
    double sample_cost_ms(double frame_ms) const override { return expected_sample_cost_ms(frame_ms, stride_, min_sample_ms_); }

    const Accelerator& built() const {
        if (!chosen_) throw std::logic_error("auto accelerator used before build()");
        return *chosen_;
    }

    const Scene& scene_;
    const FlatScene& flat_;
    CanopyOptions options_;
    std::shared_ptr<WorkloadSample> sample_;  // what candidates are timed with
    uint32_t stride_ = 1;         // the sample traces one tile in stride_
    bool warmed_up_ = false;      // this build's first tree has traced its warm-up (half a sample)
    double min_sample_ms_ = 0.0;  // a shorter sample is traced again with more tiles (next_sample_stride)
    std::vector<PrimRef> refs_;   // made by prepare(), untimed, for the first flat candidate
    AutoChoice choice_;
    std::map<std::string, std::unique_ptr<CanopyAccelerator>> trees_;  // the calibration's trees still wanted
    const CanopyAccelerator* last_ = nullptr;
    std::unique_ptr<CanopyAccelerator> chosen_;
};

// The accelerators of the structure families other than the BVH, by the names accel/builder.h's other_families()
// lists.
struct FamilyFactory {
    const char* name;
    std::unique_ptr<Accelerator> (*make)(const FlatScene&, const CanopyOptions&);
};
constexpr FamilyFactory kFamilies[] = {{kKdTreeName, &make_kd_accelerator}};

std::unique_ptr<Accelerator> make_family_accelerator(const FlatScene& flat, const CanopyOptions& options) {
    for (const FamilyFactory& family : kFamilies)
        if (options.builder == family.name) return family.make(flat, options);
    return nullptr;
}

}  // namespace

CollapseMethod collapse_of(const CanopyOptions& options) {
    if (options.collapse) return *options.collapse;
    const bool direct = options.builder == "lbvh" && options.toplevel == "flat" && kernel_width(options.kernel) > 2;
    return direct ? CollapseMethod::Direct : CollapseMethod::Optimal;
}

void check_collapse_options(const CanopyOptions& options) {
    if (options.collapse != CollapseMethod::Direct) return;
    const auto refuse = [](const std::string& what) {
        throw std::invalid_argument("collapse 'direct' is lbvh's wide tree from its Morton codes: builder lbvh, kernel bvh4 or bvh8 "
                                    "and a flat top level, not " + what);
    };
    if (options.builder != "lbvh") refuse("builder '" + options.builder + "'");
    if (const int width = kernel_width(options.kernel); width == 2) refuse("kernel " + kernel_name(width));
    if (options.toplevel != "flat") refuse("top level '" + options.toplevel + "'");
}

void check_node_layout_options(const CanopyOptions& options) {
    if (options.layout != NodeLayout::Compressed) return;
    const auto refuse = [](const std::string& what) {
        throw std::invalid_argument("compressed nodes take a named BVH builder, kernel bvh8 and a flat top level, not " + what);
    };
    // auto's candidates include two-level trees; the other structure families have no wide nodes.
    const bool family = std::any_of(std::begin(kFamilies), std::end(kFamilies), [&](const FamilyFactory& f) { return options.builder == f.name; });
    if (options.builder == "auto" || family) refuse("builder '" + options.builder + "'");
    if (const int width = kernel_width(options.kernel); width != 8) refuse("kernel " + kernel_name(width));
    if (options.toplevel != "flat") refuse("top level '" + options.toplevel + "'");
}

void check_layout_options(const CanopyOptions& options) {
    check_collapse_options(options);
    check_node_layout_options(options);
}

TwoLevelInput two_level_input(const Scene& scene) {
    TwoLevelInput input;
    std::vector<std::vector<uint32_t>> object_ids(scene.meshes.size());
    for (size_t m = 0; m < scene.meshes.size(); ++m) {
        const Mesh& mesh = scene.meshes[m];
        for (const Object& object : mesh.objects) {
            object_ids[m].push_back(uint32_t(input.objects.size()));
            std::vector<Triangle>& tris = input.objects.emplace_back();
            tris.reserve(object.triangle_count);
            for (uint32_t t = object.first_triangle; t < object.first_triangle + object.triangle_count; ++t) {
                const glm::uvec3& f = mesh.triangles[t];
                tris.push_back({mesh.positions[f.x], mesh.positions[f.y], mesh.positions[f.z]});
            }
        }
    }
    uint32_t offset = 0;
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        for (size_t o = 0; o < mesh.objects.size(); ++o)
            input.instances.push_back({object_ids[instance.mesh][o], instance.transform, offset + mesh.objects[o].first_triangle});
        offset += uint32_t(mesh.triangles.size());
    }
    return input;
}

std::unique_ptr<Accelerator> make_canopy_accelerator(const FlatScene& scene, const CanopyOptions& options) {
    if (options.builder != "auto") check_builder_name(options.builder);  // unknown names and parameters
    check_layout_options(options);
    if (options.builder == "auto") throw std::invalid_argument("builder 'auto' needs the scene's objects and instances");
    if (auto family = make_family_accelerator(scene, options)) return family;
    return std::make_unique<CanopyAccelerator>(nullptr, scene, options);
}

std::unique_ptr<Accelerator> make_canopy_accelerator(const Scene& scene, const FlatScene& flat, const CanopyOptions& options) {
    if (options.builder != "auto") check_builder_name(options.builder);  // unknown names and parameters
    check_layout_options(options);
    if (options.builder == "auto") {
        if (options.toplevel != "flat") throw std::invalid_argument("builder 'auto' chooses the top level itself: drop --toplevel");
        if (options.frames_planned < 1) throw std::invalid_argument("--frames-planned must be at least 1");
        kernel_width(options.kernel);  // an unknown kernel fails here, not at the first build
        return std::make_unique<AutoAccelerator>(scene, flat, options);
    }
    if (auto family = make_family_accelerator(flat, options)) return family;
    return std::make_unique<CanopyAccelerator>(&scene, flat, options);
}

}  // namespace canopy
