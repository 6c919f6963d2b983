#pragma once
// A protocol frame's diffuse rays, recorded once, and single-thread passes over them: how `canopy study` and
// tests/kernel_replay time kernels on the same rays, without shading, tiles or threads.
#include "renderer/frames.h"
#include "renderer/camera.h"
#include "renderer/path_tracer.h"
#include "renderer/ray_file.h"

#include <chrono>
#include <vector>

namespace canopy {

// Records every ray a tracer is asked for, and answers with the accelerator's hit.
struct RecordingTracer {
    const Accelerator& accel;
    std::vector<Ray>& rays;
    bool closest(const Ray& ray, Hit& hit) const {
        rays.push_back(ray);
        hit = accel.trace(ray);
        return hit.found();
    }
};

// Records every ray a workload's frame asks of a canopy accelerator, with the hit it answers.
struct WorkloadRecorder {
    const Accelerator& accel;
    std::vector<RecordedRay>& rays;
    bool closest(const Ray& ray, Hit& hit) const {
        hit = accel.trace(ray);
        rays.push_back({ray, false, hit});
        return hit.found();
    }
    bool occluded(const Ray& ray) const {
        Hit hit;
        accel.trace_batch(Query::Any, {&ray, 1}, {&hit, 1});
        rays.push_back({ray, true, hit});
        return hit.found();
    }
};

// Every ray of frame `frame` of the workload scene.settings names, pixel by pixel on one thread so that their order
// is fixed, as a live frame traces them: what `canopy rays record` writes.
inline std::vector<RecordedRay> record_frame(const Accelerator& accel, const ShadingScene& scene, const PinholeCamera& camera,
                                             uint32_t frame) {
    std::vector<RecordedRay> rays;
    const WorkloadRecorder recorder{accel, rays};
    Image unused(scene.settings.width, scene.settings.height);
    uint64_t count = 0;
    for (int y = 0; y < scene.settings.height; ++y)
        for (int x = 0; x < scene.settings.width; ++x) trace_pixel(recorder, scene, camera, frame, x, y, unused, count);
    return rays;
}

// The diffuse rays of one protocol frame (sample 0), traced single-threaded so their order is fixed.
inline std::vector<Ray> diffuse_rays(const Accelerator& reference, const FlatScene& flat, const PinholeCamera& camera, int w, int h) {
    std::vector<Ray> rays;
    FrameSettings settings;
    settings.width = w, settings.height = h;
    const ShadingScene shading{flat, settings};
    const RecordingTracer tracer{reference, rays};
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            Rng rng(uint64_t(y) * uint64_t(w) + uint64_t(x), 0);
            uint64_t count = 0;
            const float u = rng.next_float(), v = rng.next_float();
            Ray ray = camera.generate(x, y, u, v);
            trace_path(tracer, shading, ray, rng, count);
        }
    return rays;
}

// Single-threaded nanoseconds per ray of one pass over `rays`.
inline double pass_ns_per_ray(const Accelerator& accel, const std::vector<Ray>& rays) {
    if (rays.empty()) return 0.0;
    const auto start = std::chrono::steady_clock::now();
    for (const Ray& ray : rays) (void)accel.trace(ray);  // a virtual call: never optimised away
    return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count() / double(rays.size());
}

}  // namespace canopy
