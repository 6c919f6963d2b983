// kernel_replay: one thread traces the rays of a frame's paths, recorded once, through canopy's kernel and Embree's
// in alternating rounds, and reports each one's fastest round in ns a ray and their ratio. No shading, scheduling
// or threads in the timed loop, so kernel changes of 1% show through (frames move 2 to 5% between runs).
//   kernel_replay SCENE [BUILDER=binned] [KERNEL=bvh8] [EMBREE_QUALITY=medium] [ROUNDS=6]
#include "renderer/accelerator.h"
#include "renderer/camera.h"
#include "renderer/path_tracer.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

using namespace canopy;

namespace {

// A tracer for render_frame that keeps every ray it is asked to trace, in the order the frame traces them.
struct RecordingTracer {
    const Accelerator& accel;
    std::vector<Ray>& rays;
    bool closest(const Ray& ray, Hit& hit) const {
        rays.push_back(ray);
        hit = accel.trace(ray);
        return hit.found();
    }
};

// The protocol's paths at half the frame's resolution, one sample a pixel, every bounce's ray (on the one thread the
// caller allows, so in tile order).
std::vector<Ray> record_paths(const Accelerator& accel, const Scene& scene, const FlatScene& flat) {
    const FrameSettings settings{.width = 512, .height = 384};
    const ShadingScene shading{flat, settings};
    const PinholeCamera camera(scene_camera(scene, flat), settings.width, settings.height);
    std::vector<Ray> rays;
    Image image(settings.width, settings.height);
    render_frame(RecordingTracer{accel, rays}, shading, camera, 0, image);
    return rays;
}

// Seconds to trace every ray; `hits` keeps the results observable.
double trace_all(const Accelerator& accel, const std::vector<Ray>& rays, uint64_t& hits) {
    const auto start = std::chrono::steady_clock::now();
    for (const Ray& ray : rays) hits += accel.trace(ray).found();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s SCENE [BUILDER=binned] [KERNEL=bvh8] [EMBREE_QUALITY=medium] [ROUNDS=6]\n", argv[0]);
        return 2;
    }
    try {
        const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
        const Scene scene = load_scene(argv[1]);
        const FlatScene flat = flatten(scene);
        CanopyOptions options;
        options.builder = argc > 2 ? argv[2] : "binned";
        options.kernel = argc > 3 ? argv[3] : "bvh8";
        const std::string quality = argc > 4 ? argv[4] : "medium";
        const std::string rounds_arg = argc > 5 ? argv[5] : "6";
        if (rounds_arg.empty() || rounds_arg.find_first_not_of("0123456789") != std::string::npos || rounds_arg.size() > 6 || std::stoi(rounds_arg) < 1)
            throw std::invalid_argument("ROUNDS " + rounds_arg + ": a whole number from 1 to 999999");
        const int rounds = std::stoi(rounds_arg);
        const auto ours = make_canopy_accelerator(scene, flat, options);
        const auto embree = make_embree_accelerator(flat, quality, 1);
        for (Accelerator* accel : {ours.get(), embree.get()}) accel->prepare(), accel->build();
        const std::vector<Ray> rays = record_paths(*ours, scene, flat);
        double best_ours = 1e30, best_embree = 1e30;
        uint64_t hits_ours = 0, hits_embree = 0;
        for (int round = 0; round < rounds; ++round) {
            best_ours = std::min(best_ours, trace_all(*ours, rays, hits_ours));
            best_embree = std::min(best_embree, trace_all(*embree, rays, hits_embree));
        }
        const double ns = 1e9 / double(rays.size());
        std::printf("%s: %zu rays, %.4f hit; %s %s %.1f ns/ray, embree %s %.1f ns/ray, ratio %.3f (fastest of %d rounds)\n",
                    argv[1], rays.size(), double(hits_ours) / double(rays.size() * rounds), options.builder.c_str(),
                    ours->kernel().c_str(), best_ours * ns, quality.c_str(), best_embree * ns, best_ours / best_embree,
                    rounds);
        // Both answer the same rays: a share of hits apart by more than grazing rays explain is a wrong kernel.
        if (std::abs(double(hits_ours) - double(hits_embree)) > 1e-4 * double(hits_embree) + 1) {
            std::fprintf(stderr, "kernel_replay: canopy hit %llu rays, Embree %llu\n", (unsigned long long)hits_ours,
                         (unsigned long long)hits_embree);
            return 1;
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "kernel_replay: %s\n", e.what());
        return 1;
    }
}
