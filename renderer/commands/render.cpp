#include "renderer/commands/render.h"

#include "accel/builder.h"
#include "kernels/dispatch.h"
#include "renderer/accelerator.h"
#include "renderer/commands/heatmap.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <stdexcept>

namespace canopy {

std::string builder_names() {
    std::string names;
    for (const BuilderEntry& b : builders()) names += (names.empty() ? "" : ", ") + b.name;
    return names + ", or auto (chosen from scene statistics for --frames-planned)";
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
        find_builder(blas);
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

void run_render(RenderOptions o) {
    check_blas_builder(o.blas_builder, {o.toplevel});
    if (!o.blas_builder.empty()) o.builder = o.blas_builder;  // a two-level render has no flat BVH
    const BuildPlan plan = o.accel == "embree" ? BuildPlan{"embree", 8, false}
                                               : BuildPlan{o.builder, kernel_width(o.kernel), o.toplevel != "flat"};
    const Scene scene = load_scene_within_memory(o.scene, {&plan, 1}, o.memory_limit);
    const FlatScene flat = flatten(scene);
    std::unique_ptr<Accelerator> accel =
        o.accel == "embree" ? make_embree_accelerator(flat, o.embree_quality, o.threads)
                            : make_canopy_accelerator(scene, flat, {o.builder, o.start, o.kernel, o.traversal == "robust", o.intersector == "watertight", o.toplevel,
                                                                   o.frames_planned ? o.frames_planned : o.spp,
                                                                   uint64_t(o.size[0]) * uint64_t(o.size[1]),
                                                                   parse_collapse_method(o.collapse)});
    const auto start = std::chrono::steady_clock::now();
    accel->prepare();
    accel->build();
    const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const PinholeCamera camera(scene_camera(scene, flat), o.size[0], o.size[1]);
    if (o.heatmap) {
        const HeatmapStats h = write_heatmap(*accel, camera, o.size[0], o.size[1], o.output);
        std::printf("%s %s: per primary ray %.1f inner nodes, %.1f leaves, %.1f triangles; PNG top colour = cost %.0f -> %s\n",
                    o.builder.c_str(), accel->kernel().c_str(), h.mean_inner, h.mean_leaves, h.mean_triangles,
                    h.cost_p99, o.output.c_str());
        return;
    }

    FrameSettings settings;
    settings.width = o.size[0], settings.height = o.size[1], settings.max_bounces = o.bounces;
    settings.material_albedo = o.material_albedo;
    settings.tracer = o.tracer == "stream" ? TracerKind::Stream : TracerKind::Single;
    settings.stream_paths = o.stream_paths;
    settings.batch_traversal = parse_batch_traversal(o.batch_traversal);
    const ShadingScene shading{flat, settings};
    Image image(o.size[0], o.size[1]);
    const bool terminal = isatty(fileno(stderr));
    uint64_t rays = 0;
    const auto render_start = std::chrono::steady_clock::now();
    for (int s = 0; s < o.spp; ++s) {
        auto progress = [&](float f) { print_progress((float(s) + f) / float(o.spp)); };
        rays += accel->render(shading, camera, uint32_t(s), image,
                              terminal ? std::function<void(float)>(progress) : std::function<void(float)>());
    }
    if (terminal) std::fprintf(stderr, "\n");
    const double render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - render_start).count();
    write_exr(o.output, o.size[0], o.size[1], image.average(o.spp));
    std::printf("%s: %zu triangles%s, %s build %.1f ms, %d spp in %.2f s (%.2f Mrays/s), mean %.5f -> %s\n",
                o.scene.empty() ? "default scene" : o.scene.c_str(), flat.triangles.size(), instancing_summary(scene).c_str(),
                o.accel == "embree" ? ("embree " + o.embree_quality).c_str()
                                     : (accel->builder() + (accel->chosen().empty() ? "" : " -> " + accel->chosen())).c_str(),
                build_ms, o.spp,
                render_s, double(rays) / render_s / 1e6, image.mean(o.spp), o.output.c_str());
}

}  // namespace canopy
