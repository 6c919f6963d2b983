// kernel_replay: one thread traces the rays of a frame's paths, recorded once, through canopy's kernel and Embree's
// in alternating rounds, and reports each one's fastest round in ns a ray and their ratio. No shading, scheduling
// or threads in the timed loop, so kernel changes of 1% show through (frames move 2 to 5% between runs).
//   kernel_replay SCENE [BUILDER=binned] [KERNEL=bvh8] [EMBREE_QUALITY=medium] [ROUNDS=6]
#include "renderer/accelerator.h"
#include "renderer/camera.h"
#include "renderer/path_tracer.h"

#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

using namespace canopy;

namespace {

// The protocol's paths at half the frame's resolution, one sample a pixel, every bounce's ray in path order.
std::vector<Ray> record_paths(const Accelerator& accel, const Scene& scene, const FlatScene& flat) {
    const FrameSettings settings{.width = 512, .height = 384};
    const ShadingScene shading{flat, settings};
    const PinholeCamera camera(scene_camera(scene, flat), settings.width, settings.height);
    std::vector<Ray> rays;
    for (int y = 0; y < settings.height; ++y) {
        for (int x = 0; x < settings.width; ++x) {
            Rng rng(uint64_t(y) * settings.width + x, 0);
            Ray ray = camera.generate(x, y, rng.next_float(), rng.next_float());
            PathState path;
            for (int depth = 0;; ++depth) {
                rays.push_back(ray);
                const Hit hit = accel.trace(ray);
                if (!shade_bounce(shading, ray, hit, hit.found(), depth, path, rng, ray)) break;
            }
        }
    }
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
        const int rounds = argc > 5 ? std::stoi(argv[5]) : 6;
        const auto ours = make_canopy_accelerator(scene, flat, options);
        const auto embree = make_embree_accelerator(flat, quality, 1);
        ours->prepare(), ours->build(), embree->prepare(), embree->build();
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
        return std::abs(double(hits_ours) - double(hits_embree)) <= 1e-4 * double(hits_embree) + 1 ? 0 : 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "kernel_replay: %s\n", e.what());
        return 1;
    }
}
