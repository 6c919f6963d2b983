#pragma once
// The wavefront path tracer (`--tracer stream`): the frame's pixels in batches of at most FrameSettings::stream_paths
// paths, each batch on one thread; a batch's live paths advance one bounce at a time: their rays are sorted
// (kernels/ray_order.h), traced as one batch through the tracer's batch query, shaded by the same shade_bounce as
// the single-path tracer, and the paths still alive compacted for the next bounce. A path keeps its own random
// numbers, drawn in the same order as under `single`, so with an exact batch query every path, and so the image
// and the ray count, are the single-path tracer's (up to exact ties between triangles). Where sorted bounces lose
// (large scenes seen from outside), batches go path by path through the single-ray tracer instead, as measured
// (stream_choice.h).
//
// A batch tracer has `Scratch` (its per-thread memory, with `bytes()`) and
// `void closest(std::span<const Ray>, std::span<Record>, Scratch&) const`, where Record is its `Record` if it names
// one, else Hit: a record with `found()` that shading_surface turns into what shading reads (a Hit, through the
// scene's copy of its triangle).
#include "kernels/ray_order.h"
#include "renderer/path_tracer.h"

#include <immintrin.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <span>
#include <type_traits>

namespace canopy {

// What a stream frame cost besides tracing: filled in by render_frame_stream when the caller asks.
struct StreamStats {
    std::atomic<uint64_t> sort_ns{0};   // summed over threads: computing keys and permuting rays and paths
    std::atomic<uint64_t> bytes{0};     // every thread's memory (paths, rays, hits, keys, tracer scratch), summed
    std::atomic<uint64_t> batches{0}, path_batches{0};  // batches traced, and of them path by path (stream_choice.h)
};

// The threads a frame runs on: the arena's, within the limit --threads sets (tbb::global_control).
inline uint64_t working_threads() {
    return std::min<size_t>(size_t(tbb::this_task_arena::max_concurrency()),
                            tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// How a frame's pixels are dealt into batches: square tiles of `side` pixels, tile k (in raster order) to batch k
// mod `batches`, each tile's pixels row by row. Every batch holds the same mix of sky and geometry, so the threads
// finish together, and a batch's camera rays reach the scene tile by tile, as the single-path tracer's do, so that
// neighbouring rays find its nodes in cache (a row of spans across the whole image did not).
struct BatchPlan {
    uint64_t batches, side, width, height;

    // At most `most` paths a batch, and at least kBatchesPerThread batches a thread (a frame of fewer paths than one
    // batch would otherwise leave every other thread idle), as many as a multiple of the threads.
    static constexpr uint64_t kBatchesPerThread = 2;
    static constexpr uint64_t kSide = 16;  // a tile row is a packet's rays
    static BatchPlan of(uint64_t width, uint64_t height, uint64_t most, uint64_t threads) {
        most = std::max<uint64_t>(1, most), threads = std::max<uint64_t>(1, threads);
        uint64_t side = kSide;
        while (side > 1 && side * side > most) side /= 2;
        const uint64_t tiles = (width + side - 1) / side * ((height + side - 1) / side);
        const uint64_t per_batch = most / (side * side);
        uint64_t batches = (tiles + per_batch - 1) / per_batch;
        batches = std::max(batches, threads * kBatchesPerThread);
        batches = (batches + threads - 1) / threads * threads;
        return {std::max<uint64_t>(1, std::min(batches, tiles)), side, width, height};
    }
    // The most paths a batch holds.
    uint64_t most_paths() const {
        const uint64_t tiles = (width + side - 1) / side * ((height + side - 1) / side);
        return (tiles + batches - 1) / batches * side * side;
    }
    // Calls f(pixel) for every pixel (y * width + x) of batch `b`.
    template <class F>
    void for_each_pixel(uint64_t b, F&& f) const {
        const uint64_t tiles_x = (width + side - 1) / side, tiles = tiles_x * ((height + side - 1) / side);
        for (uint64_t t = b; t < tiles; t += batches) {
            const uint64_t x0 = t % tiles_x * side, y0 = t / tiles_x * side;
            for (uint64_t y = y0; y < std::min(y0 + side, height); ++y)
                for (uint64_t x = x0; x < std::min(x0 + side, width); ++x) f(uint32_t(y * width + x));
        }
    }
};

namespace detail {

struct StreamPath {
    PathState state;
    NeeState nee;
    Rng rng{0, 0};  // reseeded for its pixel when the path starts
    uint32_t pixel = 0;
};

// A thread's batch: paths, their current rays and hits in path order, and the rays and hits in key order. Only the
// rays are sorted: the tracer reads them in key order, and their hits go back to their paths' places, so shading
// reads paths, rays and hits in order and adds finished paths to the image in pixel order. Gathering the paths into
// key order too cost more (it was three quarters of the sort's time, the paths being larger than rays and hits).
template <class Scratch, class Record>
struct Wavefront {
    std::vector<StreamPath> paths;
    std::vector<Ray> rays, sorted_rays;
    std::vector<Record> hits, sorted_hits;
    std::vector<uint32_t> keys, order, radix_scratch;
    // A bounce's any-hit rays (nee's shadow rays, ao's probes) in path order: each ray's path (nee: its place among
    // the live paths; ao: its pixel), what it adds if it reaches its light (nee), and its answer.
    std::vector<Ray> shadow_rays;
    std::vector<uint32_t> shadow_owner;
    std::vector<Vec3> shadow_gain;
    std::vector<Record> shadow_hits;
    std::vector<Ray> sorted_shadow_rays;  // the any-hit rays in key order, and their answers
    std::vector<Record> sorted_shadow_hits;
    bool sorted = false;  // whether this bounce's rays are traced from sorted_rays into sorted_hits
    Scratch scratch;

    size_t bytes() const {
        return paths.capacity() * sizeof(StreamPath) + (rays.capacity() + sorted_rays.capacity()) * sizeof(Ray) +
               (hits.capacity() + sorted_hits.capacity()) * sizeof(Record) +
               (keys.capacity() + order.capacity() + radix_scratch.capacity() + shadow_owner.capacity()) * sizeof(uint32_t) +
               (shadow_rays.capacity() + sorted_shadow_rays.capacity()) * sizeof(Ray) + shadow_gain.capacity() * sizeof(Vec3) +
               (shadow_hits.capacity() + sorted_shadow_hits.capacity()) * sizeof(Record) + scratch.bytes();
    }

    // The first `live` rays in key order, into sorted_rays. The key's cells divide the box of these rays' origins,
    // not the scene's: a view of a small part of a large scene still sorts its rays into many cells. Rays from one
    // point (a pinhole camera's) stay in pixel order: their runs of neighbouring pixels are coherent packets already,
    // and a key of octant alone would only pay a full sort to pull the runs apart.
    void sort(uint32_t live) { sorted = sort_rays({rays.data(), live}, sorted_rays); }

    // `from` in key order into `to`, the order kept in `order`; false, with nothing written, for rays of one origin.
    bool sort_rays(std::span<const Ray> from, std::vector<Ray>& to) {
        BBox origins;
        for (const Ray& r : from)
            if (std::isfinite(r.org.x) && std::isfinite(r.org.y) && std::isfinite(r.org.z)) origins.extend(r.org);
        if (origins.lower == origins.upper) return false;
        const RayOrderKey key(origins);
        keys.resize(from.size());
        for (size_t i = 0; i < from.size(); ++i) keys[i] = key(from[i]);
        radix_order(keys, order, radix_scratch);
        to.resize(from.size());
        for (size_t i = 0; i < from.size(); ++i) to[i] = from[order[i]];
        return true;
    }

    // Every buffer grown to hold `n` paths and `shadows` any-hit rays and written once, so that the first touch of
    // fresh memory (its page faults) is paid here, once per thread, and not inside a batch whose time the stream
    // chooser measures.
    void reserve_written(size_t n, size_t shadows) {
        const auto grow = [](auto& v, size_t size) {
            if (v.capacity() < size) v.resize(size), v.clear();
        };
        for (auto* v : {&rays, &sorted_rays}) grow(*v, n);
        for (auto* v : {&hits, &sorted_hits}) grow(*v, n);
        for (auto* v : {&keys, &order, &radix_scratch}) grow(*v, std::max(n, shadows));
        grow(paths, n), grow(shadow_owner, shadows), grow(shadow_gain, shadows);
        for (auto* v : {&shadow_rays, &sorted_shadow_rays}) grow(*v, shadows);
        for (auto* v : {&shadow_hits, &sorted_shadow_hits}) grow(*v, shadows);
    }
    void clear_shadows() {
        shadow_rays.clear(), shadow_owner.clear(), shadow_gain.clear();
    }

    // The rays of this bounce in the order they are traced, and where their hits go.
    std::span<const Ray> traced_rays(uint32_t live) const { return {(sorted ? sorted_rays : rays).data(), live}; }
    std::span<Record> traced_hits(uint32_t live) {
        std::vector<Record>& into = sorted ? sorted_hits : hits;
        into.resize(live);
        return {into.data(), live};
    }

    // Each sorted ray's hit back to its path's place.
    void unsort(uint32_t live) {
        if (!sorted) return;
        hits.resize(live);
        for (uint32_t i = 0; i < live; ++i) hits[order[i]] = sorted_hits[i];
    }
};

template <class F>
uint64_t timed_ns(F&& f) {
    const auto start = std::chrono::steady_clock::now();
    f();
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count());
}

// The record a batch tracer's closest fills: its Record where it names one, else Hit.
template <class BatchTracer>
struct BatchRecord {
    using type = Hit;
};
template <class BatchTracer>
    requires requires { typename BatchTracer::Record; }
struct BatchRecord<BatchTracer> {
    using type = typename BatchTracer::Record;
};

// Shading reads the hit triangle, which tracing the whole batch has long evicted from the L1 and L2 caches (the
// single-path tracer shades it just after testing it). Fetching it this many paths ahead hides that miss.
constexpr uint32_t kShadePrefetch = 16;

// Records that carry what shading reads (Embree's) have nothing to fetch.
template <class Record>
[[gnu::always_inline]] inline void prefetch_hit_triangle(const ShadingScene& scene, const std::vector<Record>& hits,
                                                         uint32_t i, uint32_t live) {
    if constexpr (std::is_same_v<Record, Hit>) {
        if (i < live && hits[i].found()) _mm_prefetch(reinterpret_cast<const char*>(&scene.flat.triangles[hits[i].prim]), _MM_HINT_T0);
    }
}

}  // namespace detail

// What shading reads of a batch tracer's Hit: the scene's copy of its triangle.
[[gnu::always_inline]] inline SurfaceHit shading_surface(const ShadingScene& scene, const Ray&, const Hit& hit) {
    return triangle_surface(scene.flat.triangles[hit.prim], hit);
}

namespace detail {

// One batch as a wavefront: its paths advance one bounce at a time, each bounce's rays sorted and traced as one batch.
// Returns rays traced; adds the time spent sorting to `sort_ns`.
template <class BatchTracer, class Wavefront>
uint64_t trace_wavefront(const BatchTracer& tracer, const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame,
                         const BatchPlan& plan, uint64_t b, Wavefront& wf, Image& accumulated, uint64_t& sort_ns) {
    const int w = scene.settings.width;
    wf.paths.clear();
    wf.rays.clear();
    plan.for_each_pixel(b, [&](uint32_t pixel) {
        const int x = int(pixel % uint32_t(w)), y = int(pixel / uint32_t(w));
        wf.paths.push_back({PathState{}, NeeState{}, Rng(uint64_t(y) * uint64_t(w) + uint64_t(x), frame), pixel});
        const float u = wf.paths.back().rng.next_float(), v = wf.paths.back().rng.next_float();
        wf.rays.push_back(camera.generate(x, y, u, v));
    });
    uint32_t live = uint32_t(wf.paths.size());
    uint64_t traced = 0;
    for (int depth = 0; live > 0; ++depth) {
        sort_ns += timed_ns([&] { wf.sort(live); });
        tracer.closest(wf.traced_rays(live), wf.traced_hits(live), wf.scratch);
        sort_ns += timed_ns([&] { wf.unsort(live); });
        traced += live;
        uint32_t next_live = 0;
        wf.clear_shadows();
        const auto finish = [&](uint32_t pixel, const Vec3& radiance) {
            accumulated.add(int(pixel % uint32_t(w)), int(pixel / uint32_t(w)), radiance);
        };
        for (uint32_t i = 0; i < live; ++i) {
            prefetch_hit_triangle(scene, wf.hits, i + kShadePrefetch, live);
            StreamPath& path = wf.paths[i];
            Ray next;
            const bool found = wf.hits[i].found();
            const SurfaceHit surface = found ? shading_surface(scene, wf.rays[i], wf.hits[i]) : SurfaceHit{};
            switch (scene.settings.workload) {
            case Workload::Diffuse:
                if (shade_bounce(scene, wf.rays[i], found, surface, depth, path.state, path.rng, next)) {
                    wf.paths[next_live] = path;
                    wf.rays[next_live++] = next;
                } else {
                    finish(path.pixel, path.state.radiance);
                }
                break;
            case Workload::Camera: finish(path.pixel, camera_radiance(scene, wf.rays[i], found, surface)); break;
            case Workload::Ao: {
                if (!found) {
                    finish(path.pixel, Vec3(1.0f));
                    break;
                }
                const Ray base = ao_base(scene, wf.rays[i], surface);
                for (int k = 0; k < scene.settings.ao_rays; ++k) {
                    wf.shadow_rays.push_back(ao_probe(base, path.rng));
                    wf.shadow_owner.push_back(path.pixel);
                }
                break;
            }
            case Workload::Nee: {
                std::optional<ShadowRay> shadow;
                if (!nee_bounce(scene, wf.rays[i], found, surface, depth, path.state, path.nee, path.rng, next, shadow)) {
                    finish(path.pixel, path.state.radiance);  // no shadow ray: a path casts one only to go on
                    break;
                }
                if (shadow) {
                    wf.shadow_rays.push_back(shadow->ray);
                    wf.shadow_owner.push_back(next_live);
                    wf.shadow_gain.push_back(shadow->contribution);
                }
                wf.paths[next_live] = path;
                wf.rays[next_live++] = next;
                break;
            }
            }
        }
        traced += trace_shadows(tracer, scene, wf, finish);
        live = next_live;
    }
    return traced;
}

// A bounce's any-hit rays in one batch: a nee shadow ray that reaches its light adds its gain to its path; ao's
// probes give their pixel the share that reached nothing. Returns rays traced.
template <class BatchTracer, class Wavefront, class Finish>
uint64_t trace_shadows(const BatchTracer& tracer, const ShadingScene& scene, Wavefront& wf, const Finish& finish) {
    const size_t n = wf.shadow_rays.size();
    if (n == 0) return 0;
    wf.shadow_hits.resize(n);
    // nee's shadow rays leave the bounce's scattered hit points: sorted, they form coherent packets. ao's probes,
    // a pixel's few from one point in pixel order, traced as fast unsorted, and Embree's stream call slower sorted
    // (docs/results.md#workloads-against-embrees-best-call).
    if (scene.settings.workload == Workload::Nee && wf.sort_rays(wf.shadow_rays, wf.sorted_shadow_rays)) {
        wf.sorted_shadow_hits.resize(n);
        tracer.occluded(wf.sorted_shadow_rays, wf.sorted_shadow_hits, wf.scratch);
        for (size_t i = 0; i < n; ++i) wf.shadow_hits[wf.order[i]] = wf.sorted_shadow_hits[i];
    } else {
        tracer.occluded(wf.shadow_rays, wf.shadow_hits, wf.scratch);
    }
    if (scene.settings.workload == Workload::Nee) {
        for (size_t k = 0; k < n; ++k)
            if (!wf.shadow_hits[k].found()) wf.paths[wf.shadow_owner[k]].state.radiance += wf.shadow_gain[k];
        return n;
    }
    const size_t per_pixel = size_t(scene.settings.ao_rays);
    for (size_t first = 0; first < n; first += per_pixel) {
        int open = 0;
        for (size_t k = first; k < first + per_pixel; ++k) open += !wf.shadow_hits[k].found();
        finish(wf.shadow_owner[first], ao_radiance(open, int(per_pixel)));
    }
    return n;
}

// One batch path by path through the single-ray tracer, in the batch's tile order. Returns rays traced.
template <class SingleTracer>
uint64_t trace_paths(const SingleTracer& single, const ShadingScene& scene, const PinholeCamera& camera, uint32_t frame,
                     const BatchPlan& plan, uint64_t b, Image& accumulated) {
    const uint32_t w = uint32_t(scene.settings.width);
    uint64_t traced = 0;
    plan.for_each_pixel(b, [&](uint32_t pixel) {
        trace_pixel(single, scene, camera, frame, int(pixel % w), int(pixel / w), accumulated, traced);
    });
    return traced;
}

}  // namespace detail

// Renders one sample per pixel of frame `frame` into `accumulated`, as render_frame does, each batch either as a
// wavefront through the tracer's batch query or path by path through `single`, as scene.stream_chooser decides
// (stream_choice.h). Returns rays traced. `on_batch` (optional) is called after each batch with the fraction of the
// frame done.
template <class BatchTracer, class SingleTracer>
uint64_t render_frame_stream(const BatchTracer& tracer, const SingleTracer& single, const ShadingScene& scene,
                             const PinholeCamera& camera, uint32_t frame, Image& accumulated,
                             const std::function<void(float)>& on_batch = {}) {
    StreamStats* const stats = scene.stream_stats;
    StreamChooser& chooser = *scene.stream_chooser;
    const BatchPlan plan = BatchPlan::of(uint64_t(scene.settings.width), uint64_t(scene.settings.height),
                                         scene.settings.stream_paths, working_threads());
    if (chooser.whole_frame_by_paths(scene.settings.stream_batching)) {
        // Path by path through the single-ray tracer's own tiles, balanced over the threads as finely as its frames are.
        const uint64_t rays = render_frame(single, scene, camera, frame, accumulated, on_batch);
        if (stats) stats->batches += plan.batches, stats->path_batches += plan.batches;
        return rays;
    }
    using Record = typename detail::BatchRecord<BatchTracer>::type;
    using Wavefront = detail::Wavefront<typename BatchTracer::Scratch, Record>;
    static tbb::enumerable_thread_specific<Wavefront> wavefronts;  // reused from frame to frame
    std::atomic<uint64_t> rays{0}, done{0}, sort_ns{0}, path_batches{0};
    tbb::parallel_for(uint64_t(0), plan.batches, uint64_t(1), [&](uint64_t b) {
        const StreamChooser::Way way = chooser.next(scene.settings.stream_batching);
        uint64_t traced = 0, sorting = 0;
        Wavefront* wf = nullptr;
        size_t bytes = 0;
        if (way == StreamChooser::Way::Wavefront) {
            wf = &wavefronts.local();
            const uint64_t paths = plan.most_paths();
            wf->reserve_written(paths, scene.settings.workload == Workload::Ao ? paths * uint64_t(scene.settings.ao_rays)
                                       : scene.settings.workload == Workload::Nee ? paths : 0);
            bytes = wf->bytes();
        }
        const uint64_t ns = detail::timed_ns([&] {
            if (wf) traced = detail::trace_wavefront(tracer, scene, camera, frame, plan, b, *wf, accumulated, sorting);
            else traced = detail::trace_paths(single, scene, camera, frame, plan, b, accumulated);
        });
        const bool counted = !wf || wf->bytes() == bytes;  // a batch that grew its buffers after all paid for fresh memory
        chooser.record(way, ns, traced, counted);
        rays += traced;
        sort_ns += sorting;
        path_batches += way == StreamChooser::Way::Paths;
        if (on_batch) on_batch(float(done.fetch_add(1) + 1) / float(plan.batches));
    });
    if (stats) {
        stats->sort_ns += sort_ns;
        stats->batches += plan.batches;
        stats->path_batches += path_batches;
        uint64_t all = 0;  // the threads that have traced batches, each with the memory its largest batch took
        for (const Wavefront& wf : wavefronts) all += wf.bytes();
        stats->bytes = std::max(stats->bytes.load(), all);
    }
    return rays;
}

}  // namespace canopy
