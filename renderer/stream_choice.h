#pragma once
// How the stream tracer (`--tracer stream`) traces each of its batches: as a wavefront (every path one bounce at a
// time, each bounce's rays sorted and traced as one batch) or path by path through the single-ray query, in the
// batch's tile order. Both trace the same paths with the same random numbers, so they give the same image and rays;
// only their speed differs, and which is faster depends on the scene and view: sorted bounces win inside a room,
// where the rays of a bounce share the nodes they visit, and lose on large scenes seen from outside, where a batch's
// bounces scatter over more nodes than the caches hold (docs/results.md#the-stream-tracer-on-every-scene).
#include <array>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <string>

namespace canopy {

enum class StreamBatching : uint8_t {
    Measured,   // each batch the way measured fastest so far (StreamChooser)
    Wavefront,  // every batch as a wavefront
    Paths,      // every batch path by path
};

inline StreamBatching parse_stream_batching(const std::string& name) {
    if (name == "measured") return StreamBatching::Measured;
    if (name == "wavefront") return StreamBatching::Wavefront;
    if (name == "paths") return StreamBatching::Paths;
    throw std::invalid_argument("unknown --stream-batches '" + name + "' (known: measured, wavefront, paths)");
}
inline const char* stream_batching_name(StreamBatching batching) {
    return batching == StreamBatching::Measured ? "measured" : batching == StreamBatching::Wavefront ? "wavefront" : "paths";
}
constexpr const char* kStreamBatchingHelp =
    "Stream tracer: each batch as a wavefront, path by path, or measured (the faster way so far, tried both ways first)";

// Chooses each batch's way from the time per ray that batches of each way took in this render. It first tries each
// way kProbes times (a wavefront batch that had to grow its buffers is not counted: its first touch of fresh memory is
// not what the next batches pay), then takes the faster one; while the two are within kClose of each other it tries the
// slower one again now and then (at the 2^k-th choice), so that a first measurement taken in noise is corrected at a
// cost that fades with the render's length.
class StreamChooser {
public:
    enum class Way : uint8_t { Wavefront, Paths };
    static constexpr double kClose = 1.10;
    static constexpr int kProbes = 2;  // counted batches of each way before the faster is taken for good

    Way next(StreamBatching batching) {
        if (batching == StreamBatching::Wavefront) return Way::Wavefront;
        if (batching == StreamBatching::Paths) return Way::Paths;
        const std::lock_guard lock(mutex_);
        const Way way = choose();
        ++of(way).in_flight;
        return way;
    }

    // Whether the whole frame goes path by path: the faster way by more than kClose, or the one asked for. The
    // single-ray tracer's frame, split into finer tiles than batches, balances its threads better than batches do.
    bool whole_frame_by_paths(StreamBatching batching) const {
        if (batching != StreamBatching::Measured) return batching == StreamBatching::Paths;
        const std::lock_guard lock(mutex_);
        const Cost &wave = costs_[size_t(Way::Wavefront)], &paths = costs_[size_t(Way::Paths)];
        return std::min(wave.counted, paths.counted) >= kProbes && wave.per_ray() > kClose * paths.per_ray();
    }

    // A batch of way `way` took `ns` for `rays` rays; `counted` is false for a batch whose time is not representative.
    void record(Way way, uint64_t ns, uint64_t rays, bool counted) {
        const std::lock_guard lock(mutex_);
        Cost& c = of(way);
        --c.in_flight;
        if (!counted || rays == 0) return;
        c.ns += double(ns), c.rays += double(rays), ++c.counted;
    }

private:
    struct Cost {
        double ns = 0, rays = 0;
        uint64_t counted = 0;
        int in_flight = 0;
        double per_ray() const { return ns / rays; }
    };
    Cost& of(Way way) { return costs_[size_t(way)]; }

    Way choose() {
        const Cost &wave = of(Way::Wavefront), &paths = of(Way::Paths);
        const auto tried = [](const Cost& c) { return c.counted + uint64_t(c.in_flight); };
        if (std::min(wave.counted, paths.counted) < kProbes) return tried(paths) < tried(wave) ? Way::Paths : Way::Wavefront;
        const bool close = std::max(wave.per_ray(), paths.per_ray()) < kClose * std::min(wave.per_ray(), paths.per_ray());
        const Way faster = wave.per_ray() <= paths.per_ray() ? Way::Wavefront : Way::Paths;
        ++choices_;
        const bool retry = close && (choices_ & (choices_ - 1)) == 0;
        return retry ? (faster == Way::Wavefront ? Way::Paths : Way::Wavefront) : faster;
    }

    mutable std::mutex mutex_;
    std::array<Cost, 2> costs_;
    uint64_t choices_ = 0;
};

}  // namespace canopy
