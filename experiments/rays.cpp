#include "experiments/rays.h"

#include "base/output_path.h"
#include "engine/accelerator.h"
#include "renderer/camera.h"
#include "renderer/recorded_rays.h"
#include "scenes/scene.h"

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <memory>

namespace canopy {

void run_record(const RecordOptions& o) {
    const Scene scene = load_scene(o.scene);
    const FlatScene flat = flatten(scene);
    CanopyOptions options;
    options.builder = o.builder, options.kernel = o.kernel;
    const std::unique_ptr<Accelerator> accel = make_canopy_accelerator(scene, flat, options);
    accel->prepare();
    accel->build();
    FrameSettings settings;
    settings.width = o.size[0], settings.height = o.size[1], settings.max_bounces = o.bounces;
    settings.material_albedo = o.material_albedo;
    o.workload.apply(settings);
    const ShadingScene shading{flat, settings};
    const PinholeCamera camera(scene_camera(scene, flat), settings.width, settings.height);
    const auto start = std::chrono::steady_clock::now();
    const std::vector<RecordedRay> rays = record_frame(*accel, shading, camera, uint32_t(o.frame));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    write_rays(o.output, rays);
    size_t any = 0, hits = 0;
    for (const RecordedRay& r : rays) any += r.any, hits += r.hit.found();
    std::printf("%s: frame %d of workload %s at %dx%d through %s %s: %zu rays (%zu any hit), %zu hit, recorded in %.2f s -> %s\n",
                o.scene.c_str(), o.frame, o.workload.workload.c_str(), settings.width, settings.height, accel->builder().c_str(),
                accel->kernel().c_str(), rays.size(), any, hits, seconds, o.output.c_str());
}

void register_rays(CLI::App& canopy) {
    CLI::App* rays = canopy.add_subcommand("rays", "A renderer's rays: record a frame's rays to replay them with bench --rays");
    rays->require_subcommand(1);
    auto r = std::make_shared<RecordOptions>();
    CLI::App* record = rays->add_subcommand("record", "Write one frame's rays of a workload and the hits they got (.npy, docs/workloads.md)");
    record->add_option("scene", r->scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    record->add_option("-o,--output", r->output, "Ray file (.npy)")->capture_default_str();
    add_workload_options(*record, r->workload);
    record->add_option("--size", r->size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    record->add_option("--bounces", r->bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    record->add_option("--frame", r->frame, "Frame whose random numbers the rays follow (bench times frames 1, 2, ...)")
        ->check(CLI::Range(0, 1 << 30))->capture_default_str();
    record->add_option("--builder", r->builder, "Builder of the tree that answers the recorded rays")->capture_default_str();
    record->add_option("--kernel", r->kernel, "Its kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    record->add_flag("--materials", r->material_albedo, "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light");
    record->callback([r] {
        check_output_path("-o", r->output, {".npy"});
        run_record(*r);
    });
}

}  // namespace canopy
