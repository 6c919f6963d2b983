// kernel_replay: one thread traces the rays of a frame's paths, recorded once, through canopy's kernel and Embree's
// in alternating rounds, and reports each one's fastest round in ns a ray and their ratio. No shading, scheduling
// or threads in the timed loop, so kernel changes of 1% show through (frames move 2 to 5% between runs).
// PASS `frames` times whole one-thread frames instead (the same resolution, each accelerator's own render path, so
// shading included and every ray waiting on the hit before it), in the same alternation.
//   kernel_replay SCENE [BUILDER=binned] [KERNEL=bvh8] [EMBREE_QUALITY=medium] [ROUNDS=6] [PASS=rays|frames]
#include "renderer/recorded_rays.h"
#include "experiments/embree_accelerator.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

using namespace canopy;

namespace {

// The protocol's paths at half the frame's resolution, one sample a pixel, every bounce.
constexpr int kWidth = 512, kHeight = 384;

uint64_t hits(const Accelerator& accel, const std::vector<Ray>& rays) {
    uint64_t found = 0;
    for (const Ray& ray : rays) found += accel.trace(ray).found();
    return found;
}

// One single-thread frame of the protocol's paths at the replay's resolution (frame 0's seeds), in ns a ray.
double frame_ns_per_ray(const Accelerator& accel, const ShadingScene& shading, const PinholeCamera& camera, Image& image) {
    const auto start = std::chrono::steady_clock::now();
    const uint64_t rays = render(accel, shading, camera, 0, image);
    return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count() / double(rays);
}

int rounds_of(const std::string& text) {
    if (text.empty() || text.size() > 6 || text.find_first_not_of("0123456789") != std::string::npos || std::stoi(text) < 1)
        throw std::invalid_argument("ROUNDS " + text + ": a whole number from 1 to 999999");
    return std::stoi(text);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s SCENE [BUILDER=binned] [KERNEL=bvh8] [EMBREE_QUALITY=medium] [ROUNDS=6] [PASS=rays|frames]\n",
                     argv[0]);
        return 2;
    }
    try {
        const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
        CanopyOptions options;
        options.builder = argc > 2 ? argv[2] : "binned";
        options.kernel = argc > 3 ? argv[3] : "bvh8";
        const std::string quality = argc > 4 ? argv[4] : "medium";
        const int rounds = rounds_of(argc > 5 ? argv[5] : "6");
        const std::string pass = argc > 6 ? argv[6] : "rays";
        if (pass != "rays" && pass != "frames") throw std::invalid_argument("PASS " + pass + ": rays or frames");
        const Scene scene = load_scene(argv[1]);
        const FlatScene flat = flatten(scene);
        const auto ours = make_canopy_accelerator(scene, flat, options);
        const auto embree = make_embree_accelerator(flat, quality, 1);
        for (Accelerator* accel : {ours.get(), embree.get()}) accel->prepare(), accel->build();
        const PinholeCamera camera(scene_camera(scene, flat), kWidth, kHeight);
        const std::vector<Ray> rays = diffuse_rays(*ours, flat, camera, kWidth, kHeight);
        FrameSettings settings;
        settings.width = kWidth, settings.height = kHeight;
        const ShadingScene shading{flat, settings};
        Image image(kWidth, kHeight);
        const auto time = [&](const Accelerator& accel) {
            return pass == "rays" ? pass_ns_per_ray(accel, rays) : frame_ns_per_ray(accel, shading, camera, image);
        };
        double ours_ns = 1e30, embree_ns = 1e30;
        for (int round = 0; round < rounds; ++round) {
            ours_ns = std::min(ours_ns, time(*ours));
            embree_ns = std::min(embree_ns, time(*embree));
        }
        const uint64_t ours_hits = hits(*ours, rays), embree_hits = hits(*embree, rays);
        std::printf("%s: %zu rays, %.4f hit; %s: %s %s %.1f ns/ray, embree %s %.1f ns/ray, ratio %.3f (fastest of %d rounds)\n",
                    argv[1], rays.size(), double(ours_hits) / double(rays.size()), pass.c_str(), options.builder.c_str(),
                    ours->kernel().c_str(), ours_ns, quality.c_str(), embree_ns, ours_ns / embree_ns, rounds);
        // Both answer the same rays: a share of hits apart by more than grazing rays explain is a wrong kernel.
        if (std::abs(double(ours_hits) - double(embree_hits)) > 1e-4 * double(embree_hits) + 1) {
            std::fprintf(stderr, "kernel_replay: canopy hit %llu rays, Embree %llu\n", (unsigned long long)ours_hits,
                         (unsigned long long)embree_hits);
            return 1;
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "kernel_replay: %s\n", e.what());
        return 1;
    }
}
