#pragma once
// The path tracers over the kernels of one width, compiled in a translation unit of their own per width
// (frames_bvh2.cpp, frames_bvh4.cpp, frames_bvh8.cpp; the kd-tree's with width 1), so that no one file compiles every
// kernel's frames.
#include "kernels/dispatch.h"
#include "renderer/frames.h"
#include "renderer/path_tracer.h"
#include "renderer/wavefront.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <stdexcept>
#include <variant>

namespace canopy {

// What a frame call asks: the scene and its settings, the camera, the frame's number, the image and its progress.
struct FrameJob {
    const ShadingScene& scene;
    const PinholeCamera& camera;
    uint32_t frame;
    Image& image;
    const std::function<void(float)>& on_tile;
};

template <class Kernel>
constexpr int width_of_kernel = 1;  // the kd-tree's
template <class Layout, bool Robust, class Test>
constexpr int width_of_kernel<BvhKernel<Layout, Robust, Test>> = Layout::kWidth;

// The width of the kernel `kernel` holds (0 for none).
inline int kernel_width_of(const AnyKernel& kernel) {
    return std::visit([]<class Kernel>(const Kernel&) {
        if constexpr (std::is_same_v<Kernel, std::monostate>) return 0;
        else return width_of_kernel<Kernel>;
    }, kernel);
}

// The stream tracer's view of a kernel: each bounce's batch in one call.
template <class Kernel>
struct BatchTracer {
    using Scratch = typename Kernel::Scratch;
    Kernel kernel;
    BatchTraversal how;
    void closest(std::span<const Ray> rays, std::span<Hit> hits, Scratch& scratch) const {
        kernel.template batch<Query::Closest>(rays, hits, scratch, how);
    }
    void occluded(std::span<const Ray> rays, std::span<Hit> hits, Scratch& scratch) const {
        kernel.template batch<Query::Any>(rays, hits, scratch, how);
    }
};

// The single-ray tracer through the counting kernel, each thread adding to its own counts.
template <class Kernel>
struct CountingTracer {
    Kernel kernel;
    tbb::enumerable_thread_specific<TraversalCounts>& counts;
    bool closest(const Ray& ray, Hit& hit) const { return kernel.query(ray, hit, counts.local()); }
    bool occluded(const Ray& ray) const {
        Hit hit;
        return kernel.template query<Query::Any>(ray, hit, counts.local());
    }
};

// Calls f(kernel) for a kernel of width N; instantiated for each width in its own translation unit.
template <int N, class F>
uint64_t with_kernel_of_width(const AnyKernel& kernel, F&& f) {
    return std::visit([&]<class Kernel>(const Kernel& k) -> uint64_t {
        if constexpr (!std::is_same_v<Kernel, std::monostate> && width_of_kernel<Kernel> == N && is_compiled_kernel<Kernel>)
            return f(k);
        else
            throw std::logic_error("a kernel reached the frames of another width");
    }, kernel);
}

template <int N>
uint64_t render_of_width(const AnyKernel& kernel, const FrameJob& job) {
    return with_kernel_of_width<N>(kernel, [&]<class Kernel>(const Kernel& k) -> uint64_t {
        if (job.scene.settings.tracer == TracerKind::Stream) {
            if constexpr (Kernel::kStreams)
                return render_frame_stream(BatchTracer<Kernel>{k, job.scene.settings.batch_traversal}, k, job.scene,
                                           job.camera, job.frame, job.image, job.on_tile);
            else
                throw std::invalid_argument("layout 'compressed': the single-ray tracer only, not the stream tracer");
        }
        return render_frame(k, job.scene, job.camera, job.frame, job.image, job.on_tile);
    });
}

template <int N>
uint64_t count_of_width(const AnyKernel& kernel, const FrameJob& job, tbb::enumerable_thread_specific<TraversalCounts>& counts) {
    return with_kernel_of_width<N>(kernel, [&]<class Kernel>(const Kernel& k) -> uint64_t {
        return render_frame(CountingTracer<Kernel>{k, counts}, job.scene, job.camera, job.frame, job.image);
    });
}

// Recorded rays on every thread, kReplayChunk a task: one at a time through `one(ray, any, hit)` (TracerKind::Single),
// or each chunk as two batches, its closest-hit rays then its any-hit rays, through `batch(any, rays, hits, scratch)`
// with the thread's own Scratch. Each thread's gather buffers live across its chunks: a timed pass allocates nothing
// once warm.
template <class Scratch, class One, class Batch>
void replay_chunks(TracerKind tracer, std::span<const RecordedRay> rays, std::span<Hit> hits, One&& one, Batch&& batch) {
    struct Local {
        Scratch scratch;
        std::vector<Ray> rays;
        std::vector<Hit> answers;
        std::vector<uint32_t> index;
    };
    tbb::enumerable_thread_specific<Local> locals;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), kReplayChunk), [&](const tbb::blocked_range<size_t>& range) {
        const auto chunk = rays.subspan(range.begin(), range.size());
        const auto out = hits.subspan(range.begin(), range.size());
        if (tracer == TracerKind::Single) {
            for (size_t i = 0; i < chunk.size(); ++i) one(chunk[i].ray, chunk[i].any, out[i]);
            return;
        }
        Local& local = locals.local();
        for (const bool any : {false, true}) {
            local.rays.clear(), local.index.clear();
            for (uint32_t i = 0; i < chunk.size(); ++i)
                if (chunk[i].any == any) local.rays.push_back(chunk[i].ray), local.index.push_back(i);
            local.answers.resize(local.rays.size());
            batch(any, std::span<const Ray>(local.rays), std::span<Hit>(local.answers), local.scratch);
            for (size_t k = 0; k < local.index.size(); ++k) out[local.index[k]] = local.answers[k];
        }
    }, tbb::simple_partitioner());
}

template <int N>
void replay_of_width(const AnyKernel& kernel, const FrameSettings& settings, std::span<const RecordedRay> rays, std::span<Hit> hits) {
    with_kernel_of_width<N>(kernel, [&]<class Kernel>(const Kernel& k) -> uint64_t {
        replay_chunks<typename Kernel::Scratch>(
            settings.tracer, rays, hits,
            [&](const Ray& ray, bool any, Hit& hit) {
                if (any) k.template query<Query::Any>(ray, hit);
                else k.template query<Query::Closest>(ray, hit);
            },
            [&](bool any, std::span<const Ray> batch, std::span<Hit> answers, typename Kernel::Scratch& scratch) {
                if (any) k.template batch<Query::Any>(batch, answers, scratch, settings.batch_traversal);
                else k.template batch<Query::Closest>(batch, answers, scratch, settings.batch_traversal);
            });
        return 0;
    });
}

extern template uint64_t render_of_width<1>(const AnyKernel&, const FrameJob&);
extern template uint64_t render_of_width<2>(const AnyKernel&, const FrameJob&);
extern template uint64_t render_of_width<4>(const AnyKernel&, const FrameJob&);
extern template uint64_t render_of_width<8>(const AnyKernel&, const FrameJob&);
extern template uint64_t count_of_width<1>(const AnyKernel&, const FrameJob&, tbb::enumerable_thread_specific<TraversalCounts>&);
extern template uint64_t count_of_width<2>(const AnyKernel&, const FrameJob&, tbb::enumerable_thread_specific<TraversalCounts>&);
extern template uint64_t count_of_width<4>(const AnyKernel&, const FrameJob&, tbb::enumerable_thread_specific<TraversalCounts>&);
extern template uint64_t count_of_width<8>(const AnyKernel&, const FrameJob&, tbb::enumerable_thread_specific<TraversalCounts>&);
extern template void replay_of_width<1>(const AnyKernel&, const FrameSettings&, std::span<const RecordedRay>, std::span<Hit>);
extern template void replay_of_width<2>(const AnyKernel&, const FrameSettings&, std::span<const RecordedRay>, std::span<Hit>);
extern template void replay_of_width<4>(const AnyKernel&, const FrameSettings&, std::span<const RecordedRay>, std::span<Hit>);
extern template void replay_of_width<8>(const AnyKernel&, const FrameSettings&, std::span<const RecordedRay>, std::span<Hit>);

}  // namespace canopy
