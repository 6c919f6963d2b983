#pragma once
// Frames of an engine accelerator: the path tracers instantiated over each kernel of canopy's and dispatched once
// per frame by its type, or handed to an accelerator of another library that traces frames its own way.
#include "engine/accelerator.h"
#include "renderer/path_tracer.h"
#include "renderer/ray_file.h"

#include <functional>
#include <span>
#include <utility>

namespace canopy {

// An accelerator whose rays go through another library's calls (Embree's): it renders its frames itself, with the
// same path tracer templates over a tracer type of its own.
class ForeignFrames {
public:
    virtual ~ForeignFrames() = default;
    virtual uint64_t render(const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame, Image& image,
                            const std::function<void(float)>& on_tile) const = 0;
    virtual void replay(const FrameSettings& settings, std::span<const RecordedRay> rays, std::span<Hit> hits) const = 0;
};

// Recorded rays (`bench --rays`) traced again by `accel` on every thread, their hits into `hits` (an any-hit query's
// hit is found or not): one at a time (TracerKind::Single) or in batches of one query kind (Stream: canopy's batch
// kernel, Embree's stream or packet calls), chunk by chunk in the recorded order.
void replay(const Accelerator& accel, const FrameSettings& settings, std::span<const RecordedRay> rays, std::span<Hit> hits);
// Rays recorded and replayed are traced in chunks of this many, each chunk on one thread.
constexpr size_t kReplayChunk = 4096;

// Renders frame `frame` of `accel` into `image` (the single or stream tracer, as scene.settings says). Returns rays
// traced. Throws std::invalid_argument for a compressed layout and the stream tracer.
uint64_t render(const Accelerator& accel, const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame,
                Image& image, const std::function<void(float)>& on_tile = {});

// Frame `frame` as render() traces it one ray at a time, every ray through the counting kernel: what the frame's rays
// visited in all, and how many there were. Untimed (the counts cost time); throws std::invalid_argument for an
// accelerator that cannot count (Embree).
std::pair<TraversalCounts, uint64_t> count_frame(const Accelerator& accel, const ShadingScene& scene,
                                                 const PinholeCamera& camera, uint32_t frame);

// What a render or bench holds beside its trees: `images` images and, for the stream tracer, its batches.
uint64_t frame_bytes(int width, int height, size_t images, bool stream, uint32_t stream_paths);

// `--builder auto`'s workload in the renderer: the planned frame's paths through the single-ray tracer, a sample of
// its tiles (FrameSettings::sample_stride) at a time, with the scene's camera.
std::shared_ptr<WorkloadSample> frame_sample(const Scene& scene, const FlatScene& flat, const FrameSettings& frame);

}  // namespace canopy
