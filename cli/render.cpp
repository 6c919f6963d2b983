#include "cli/render.h"
#include "base/output_path.h"
#include "experiments/embree_accelerator.h"
#include "engine/options.h"
#include "renderer/progress.h"

#include "accel/builder.h"
#include "kernels/dispatch.h"
#include "experiments/command.h"
#include "renderer/frames.h"
#include "renderer/heatmap.h"
#include "renderer/distributed.h"
#include "renderer/sample_sum.h"
#include "renderer/wavefront.h"

#include <tbb/info.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <stdexcept>

namespace canopy {

namespace {

std::string counted(size_t n, const char* one, const char* many) { return std::to_string(n) + " " + (n == 1 ? one : many); }

// " in 2 instances of 1 mesh (1 object)" for a scene that places meshes more than once, else nothing: what a
// two-level top level is built over.
std::string instancing_summary(const Scene& scene) {
    if (scene.instances.size() <= 1) return "";
    size_t objects = 0;
    for (const Mesh& mesh : scene.meshes) objects += mesh.objects.size();
    return " in " + counted(scene.instances.size(), "instance", "instances") + " of " +
           counted(scene.meshes.size(), "mesh", "meshes") + " (" + counted(objects, "object", "objects") + ")";
}

}  // namespace

namespace {

// What every rank of a render holds: the scene, and its own accelerator over it, built (replicated data).
struct PreparedRender {
    Scene scene;
    FlatScene flat;
    std::unique_ptr<Accelerator> accel;
    double build_ms = 0;
};

FrameSettings frame_settings(const RenderOptions& o) {
    FrameSettings settings;
    settings.width = o.size[0], settings.height = o.size[1], settings.max_bounces = o.bounces;
    settings.material_albedo = o.material_albedo;
    settings.tracer = o.tracer == "stream" ? TracerKind::Stream : TracerKind::Single;
    settings.stream_paths = o.stream_paths;
    settings.batch_traversal = parse_batch_traversal(o.batch_traversal);
    settings.stream_batching = parse_stream_batching(o.stream_batching);
    o.workload.apply(settings);
    return settings;
}

void prepare_render(RenderOptions& o, PreparedRender& p) {
    check_blas_builder(o.blas_builder, {o.toplevel});
    if (!o.blas_builder.empty()) o.builder = o.blas_builder;  // a two-level render has no flat BVH
    const BuildPlan plan = o.accel == "embree" ? BuildPlan{"embree", 8, false}
                                               : make_build_plan(o.builder, kernel_width(o.kernel), o.toplevel != "flat");
    p.scene = load_scene_within_memory(o.scene, {&plan, 1}, frame_bytes(o.size[0], o.size[1], 1, o.tracer == "stream", o.stream_paths),
                                       o.memory_limit);
    p.flat = flatten(p.scene);
    CanopyOptions options{o.builder, o.start, o.kernel, o.traversal == "robust", o.intersector == "watertight", o.toplevel,
                          o.frames_planned ? o.frames_planned : o.spp};
    options.auto_sample = frame_sample(p.scene, p.flat, frame_settings(o));
    if (!o.collapse.empty()) options.collapse = parse_collapse_method(o.collapse);
    options.layout = parse_node_layout(o.layout);
    if (options.layout == NodeLayout::Compressed && o.tracer == "stream")
        throw std::invalid_argument("--layout compressed: the single-ray tracer only, not --tracer stream");
    p.accel = o.accel == "embree" ? make_embree_accelerator(p.flat, o.embree_quality, o.threads)
                                  : make_canopy_accelerator(p.scene, p.flat, options);
    const auto start = std::chrono::steady_clock::now();
    p.accel->prepare();
    p.accel->build();
    p.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void render_heatmap(const RenderOptions& o, const Accelerator& accel, const PinholeCamera& camera) {
    const HeatmapStats h = write_heatmap(accel, camera, o.size[0], o.size[1], o.output);
    std::printf("%s %s: per primary ray %.1f inner nodes, %.1f leaves, %.1f triangles; PNG top colour = cost %.0f -> %s\n",
                o.builder.c_str(), accel.kernel().c_str(), h.mean_inner, h.mean_leaves, h.mean_triangles,
                h.cost_p99, o.output.c_str());
}

}  // namespace

// Under a job of several ranks (distributed.h) the samples are split between them and summed on rank 0, which
// writes the image; the image is the one process's, bit for bit (sample_sum.h).
void run_render(RenderOptions o) {
    PreparedRender p;
    distributed::checked([&] { prepare_render(o, p); });
    const PinholeCamera camera(scene_camera(p.scene, p.flat), o.size[0], o.size[1]);
    if (o.heatmap) {  // one pass of primary rays: rank 0's alone
        distributed::checked([&] { if (distributed::is_root()) render_heatmap(o, *p.accel, camera); });
        return;
    }

    const FrameSettings settings = frame_settings(o);
    const ShadingScene shading{p.flat, settings};
    const std::string what = "render " + (o.scene.empty() ? std::string("default scene") : o.scene) + ": ";
    const auto done = [&](float fraction) {
        return what + std::to_string(int(fraction * 100.0f)) + "% of " + std::to_string(o.spp) + " spp";
    };
    const auto on_progress = [&](float fraction) { progress::update(done(fraction)); };
    const auto render_start = std::chrono::steady_clock::now();
    if (progress::shown()) progress::phase(done(0.0f));
    const SampledImage image = render_samples(*p.accel, shading, camera, 0, o.spp,
                                              progress::shown() ? on_progress : std::function<void(float)>());
    if (progress::shown()) on_progress(1.0f);  // the tiles' reports may arrive out of order: the last may not be 100%
    progress::finish();
    const double render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - render_start).count();
    distributed::checked([&] {
        if (distributed::is_root()) write_image(o.output, o.size[0], o.size[1], image.sums.average(o.spp));
    });
    if (!distributed::is_root()) return;
    const std::string ranks = distributed::ranks() > 1 ? " on " + std::to_string(distributed::ranks()) + " ranks" : "";
    std::printf("%s: %zu triangles%s, %s build %.1f ms, %d spp%s in %.2f s (%.2f Mrays/s), mean %.5f -> %s\n",
                o.scene.empty() ? "default scene" : o.scene.c_str(), p.flat.triangles.size(), instancing_summary(p.scene).c_str(),
                o.accel == "embree" ? ("embree " + o.embree_quality).c_str()
                                     : (p.accel->builder() + (p.accel->chosen().empty() ? "" : " -> " + p.accel->chosen())).c_str(),
                p.build_ms, o.spp, ranks.c_str(), render_s, double(image.rays) / render_s / 1e6, image.sums.mean(o.spp),
                o.output.c_str());
    if (const AutoChoice* choice = p.accel->auto_choice(); choice && o.explain)
        std::printf("auto: %s\n%s", p.accel->reason().c_str(), explain(*choice, p.accel->frames_planned()).c_str());
}

void register_render(CLI::App& canopy) {
    auto r = std::make_shared<RenderOptions>();
    CLI::App* render = canopy.add_subcommand("render", "Render a scene to an EXR");
    render->add_option("scene", r->scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S (default: embedded scene)");
    render->add_option("-o,--output", r->output, "Output image: .exr (linear), .png or .jpg (sRGB); --heatmap: .exr")->capture_default_str();
    render->add_option("--spp", r->spp, "Samples (frames) per pixel")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    render->add_option("--size", r->size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    render->add_option("--builder", r->builder, "Builder (of a BVH, or kdtree: a kd-tree): " + builder_names())->capture_default_str();
    render->add_option("--start", r->start, "Optimisers: builder of the start tree (default: the optimiser's own)");
    render->add_option("--toplevel", r->toplevel, "flat, two-level or rebraid")
        ->check(CLI::IsMember({"flat", "two-level", "rebraid"}))->capture_default_str();
    render->add_option("--blas-builder", r->blas_builder, "Two-level top levels: builder of every object BVH (default: --builder)");
    render->add_option("--frames-planned", r->frames_planned, "Frames that --builder auto plans for (default: --spp)")
        ->check(CLI::Range(1, 1 << 24));
    render->add_flag("--explain", r->explain, "--builder auto: every candidate's predicted or measured build and frame time, and the choice");
    render->add_option("--kernel", r->kernel, "Traversal kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    render->add_option("--accel", r->accel, "canopy or embree")->check(CLI::IsMember({"canopy", "embree"}))->capture_default_str();
    render->add_option("--embree-quality", r->embree_quality, "low, medium or high")->capture_default_str();
    add_workload_options(*render, r->workload);
    render->add_option("--bounces", r->bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    render->add_option("--threads", r->threads, "Threads for every library (0: all)")->check(CLI::Range(0, 4096));
    render->add_flag("--quiet", r->quiet, kQuietHelp);
    render->add_flag("--materials", r->material_albedo,
                     "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light (protocol: 0.8 grey, sky only)");
    render->add_flag("--heatmap", r->heatmap,
                     "Instead of rendering, write what primary rays visit: EXR channels inner, leaves, triangles, and a false-colour PNG beside it");
    render->add_option("--traversal", r->traversal, "robust (padded slab test, Ize 2013) or fast")
        ->check(CLI::IsMember({"robust", "fast"}))->capture_default_str();
    render->add_option("--intersector", r->intersector, "watertight (Woop et al. 2013) or moller (Möller–Trumbore, fast)")
        ->check(CLI::IsMember({"watertight", "moller"}))->capture_default_str();
    render->add_option("--tracer", r->tracer, "single (one path at a time) or stream (each bounce's rays as one sorted batch)")
        ->check(CLI::IsMember({"single", "stream"}))->capture_default_str();
    render->add_option("--stream-paths", r->stream_paths, "Stream tracer: paths in flight per batch")
        ->check(CLI::Range(1, 1 << 24))->capture_default_str();
    render->add_option("--batch-traversal", r->batch_traversal, kBatchTraversalHelp)
        ->check(CLI::IsMember({"single", "packet", "stream"}))->capture_default_str();
    render->add_option("--stream-batches", r->stream_batching, kStreamBatchingHelp)
        ->check(CLI::IsMember({"measured", "wavefront", "paths"}))->capture_default_str();
    add_memory_limit_option(*render, r->memory_limit);
    render->add_option("--collapse", r->collapse, kCollapseHelp)->check(CLI::IsMember({"optimal", "greedy", "direct"}));
    render->add_option("--layout", r->layout, kLayoutHelp)->check(CLI::IsMember({"standard", "compressed"}))->capture_default_str();
    render->callback([r] {
        // Checked by rank 0, which writes it; a heatmap is an EXR of counts with its PNG beside.
        distributed::checked([&] {
            if (distributed::is_root()) check_output_path("-o", r->output, r->heatmap ? std::vector<std::string>{".exr"} : kImageExtensions);
        });
        const auto limit = limit_threads(r->threads);
        progress::start(r->quiet);
        run_render(*r);
    });
}

}  // namespace canopy
