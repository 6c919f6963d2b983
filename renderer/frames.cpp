#include "renderer/frames.h"

#include "renderer/camera.h"
#include "renderer/frames_of_width.h"

#include <tbb/info.h>

#include <stdexcept>

namespace canopy {
namespace {

const ForeignFrames& foreign_frames(const Accelerator& accel) {
    if (const auto* frames = dynamic_cast<const ForeignFrames*>(&accel)) return *frames;
    throw std::invalid_argument("accelerator '" + accel.library() + "' has neither a kernel of canopy's nor frames of its own");
}

}  // namespace

uint64_t render(const Accelerator& accel, const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame,
                Image& image, const std::function<void(float)>& on_tile) {
    const AnyKernel kernel = accel.bound_kernel();
    const FrameJob job{scene, camera, frame, image, on_tile};
    switch (kernel_width_of(kernel)) {
        case 0: return foreign_frames(accel).render(scene, camera, frame, image, on_tile);
        case 1: return render_of_width<1>(kernel, job);
        case 2: return render_of_width<2>(kernel, job);
        case 4: return render_of_width<4>(kernel, job);
        default: return render_of_width<8>(kernel, job);
    }
}

void replay(const Accelerator& accel, const FrameSettings& settings, std::span<const RecordedRay> rays, std::span<Hit> hits) {
    const AnyKernel kernel = accel.bound_kernel();
    switch (kernel_width_of(kernel)) {
        case 0: return foreign_frames(accel).replay(settings, rays, hits);
        case 1: return replay_of_width<1>(kernel, settings, rays, hits);
        case 2: return replay_of_width<2>(kernel, settings, rays, hits);
        case 4: return replay_of_width<4>(kernel, settings, rays, hits);
        default: return replay_of_width<8>(kernel, settings, rays, hits);
    }
}

std::pair<TraversalCounts, uint64_t> count_frame(const Accelerator& accel, const ShadingScene& scene,
                                                 const PinholeCamera& camera, uint32_t frame) {
    tbb::enumerable_thread_specific<TraversalCounts> counts;
    Image unused(scene.settings.width, scene.settings.height);
    const AnyKernel kernel = accel.bound_kernel();
    const std::function<void(float)> no_progress;
    const FrameJob job{scene, camera, frame, unused, no_progress};
    uint64_t rays = 0;
    switch (kernel_width_of(kernel)) {
        case 0: throw std::invalid_argument("accelerator '" + accel.library() + "' does not report what a ray visits: lines per ray need a canopy kernel");
        case 1: rays = count_of_width<1>(kernel, job, counts); break;
        case 2: rays = count_of_width<2>(kernel, job, counts); break;
        case 4: rays = count_of_width<4>(kernel, job, counts); break;
        default: rays = count_of_width<8>(kernel, job, counts); break;
    }
    return {counts.combine([](TraversalCounts a, const TraversalCounts& b) { return a += b; }), rays};
}

uint64_t frame_bytes(int width, int height, size_t images, bool stream, uint32_t stream_paths) {
    const uint64_t image_bytes = uint64_t(width) * uint64_t(height) * 3 * sizeof(float);
    // Per thread a batch: its paths, their rays and hits in path and in key order, and three key arrays.
    const uint64_t path_bytes = sizeof(detail::StreamPath) + 2 * (sizeof(Ray) + sizeof(Hit)) + 3 * sizeof(uint32_t);
    const uint64_t batches = stream ? uint64_t(tbb::info::default_concurrency()) * stream_paths * path_bytes : 0;
    return images * image_bytes + batches;
}

namespace {

class FrameSample final : public WorkloadSample {
public:
    FrameSample(const Scene& scene, const FlatScene& flat, const FrameSettings& frame)
        : flat_(flat), frame_(frame), camera_(scene_camera(scene, flat), frame.width, frame.height),
          scratch_(frame.width, frame.height) {
        frame_.tracer = TracerKind::Single;
    }
    uint64_t pixels() const override { return uint64_t(frame_.width) * uint64_t(frame_.height); }
    double aspect() const override { return double(frame_.width) / double(frame_.height); }
    void trace(const Accelerator& tree, uint32_t stride) override {
        FrameSettings settings = frame_;
        settings.sample_stride = stride;
        render(tree, ShadingScene{flat_, settings}, camera_, 0, scratch_);
    }
    double share(uint32_t stride) const override {
        return double(traced_pixels(frame_.width, frame_.height, stride)) / double(pixels());
    }

private:
    const FlatScene& flat_;
    FrameSettings frame_;
    PinholeCamera camera_;
    Image scratch_;  // the samples' radiance, which nothing reads
};

}  // namespace

std::shared_ptr<WorkloadSample> frame_sample(const Scene& scene, const FlatScene& flat, const FrameSettings& frame) {
    return std::make_shared<FrameSample>(scene, flat, frame);
}

}  // namespace canopy
