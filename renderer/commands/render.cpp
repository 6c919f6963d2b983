#include "renderer/commands/render.h"

#include "accel/builder.h"
#include "kernels/dispatch.h"
#include "renderer/accelerator.h"
#include "renderer/commands/heatmap.h"
#include "renderer/distributed.h"
#include "renderer/sample_sum.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <stdexcept>

namespace canopy {

std::string builder_names() {
    std::string names = "a name, or NAME:key=value,key=value with its parameters";
    for (const BuilderName& b : all_builders()) {
        names += "\n  " + b.name + ": " + b.description;
        if (is_bvh_builder(b.name)) names += builder_params_help(find_builder(b.name));
    }
    return names + "\n  auto: candidates built and timed on a sample of the frame, for --frames-planned";
}

void print_progress(float fraction) {
    const int width = 40, filled = int(fraction * float(width) + 0.5f);
    std::fprintf(stderr, "\r[%.*s%*s] %3d%%", filled, "========================================", width - filled, "",
                 int(fraction * 100.0f + 0.5f));
}

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

void check_blas_builder(const std::string& blas, const std::vector<std::string>& toplevels) {
    if (blas.empty()) return;
    if (std::none_of(toplevels.begin(), toplevels.end(), [](const std::string& t) { return t != "flat"; }))
        throw std::invalid_argument("--blas-builder " + blas + ": only --toplevel two-level or rebraid has object BVHs");
    if (blas == "auto") throw std::invalid_argument("--blas-builder auto: auto chooses a whole accelerator, not an object BVH builder");
    try {
        find_builder(parse_builder_spec(blas).name);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(std::string("--blas-builder: ") + e.what());
    }
}

Scene load_scene_within_memory(const std::string& name, std::span<const BuildPlan> plans,
                               std::optional<uint64_t> memory_limit) {
    const MemoryAvailable available = available_memory(memory_limit);
    return load_scene(name, [&](const SceneSize& size) {
        require_memory(name.empty() ? "the default scene" : name, estimate_memory(size, plans), available);
    });
}

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
    return settings;
}

void prepare_render(RenderOptions& o, PreparedRender& p) {
    check_blas_builder(o.blas_builder, {o.toplevel});
    if (!o.blas_builder.empty()) o.builder = o.blas_builder;  // a two-level render has no flat BVH
    const BuildPlan plan = o.accel == "embree" ? BuildPlan{"embree", 8, false}
                                               : BuildPlan{o.builder, kernel_width(o.kernel), o.toplevel != "flat"};
    p.scene = load_scene_within_memory(o.scene, {&plan, 1}, o.memory_limit);
    p.flat = flatten(p.scene);
    CanopyOptions options{o.builder, o.start, o.kernel, o.traversal == "robust", o.intersector == "watertight", o.toplevel,
                          o.frames_planned ? o.frames_planned : o.spp};
    options.planned_frame = frame_settings(o);
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
    // One bar, rank 0's, when its stderr is a terminal. Open MPI hands ranks their stderr as a pipe (and stdout as
    // a terminal even when mpirun's output goes to a file), so under mpirun there is none.
    const bool terminal = distributed::is_root() && isatty(fileno(stderr));
    const auto render_start = std::chrono::steady_clock::now();
    const SampledImage image = render_samples(*p.accel, shading, camera, 0, o.spp, terminal ? print_progress : nullptr);
    if (terminal) std::fprintf(stderr, "\n");
    const double render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - render_start).count();
    distributed::checked([&] {
        if (distributed::is_root()) write_exr(o.output, o.size[0], o.size[1], image.sums.average(o.spp));
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

}  // namespace canopy
