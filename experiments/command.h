#pragma once
// What the subcommands of `canopy` share: each file registers its subcommand with `register_NAME(CLI::App&)`, which
// adds the options and the callback that runs it once they are parsed (main.cpp lists them).
#include <tbb/global_control.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace canopy {

struct FrameSettings;

// The rays a frame traces (render, bench, tradeoff): --workload, --ao-rays and --ao-length.
struct WorkloadOptions {
    std::string workload = "diffuse";
    int ao_rays = 4;
    float ao_length = 0.0f;  // 0: a tenth of the scene box's diagonal
    void apply(FrameSettings& settings) const;  // throws std::invalid_argument for an unknown workload
};
void add_workload_options(CLI::App& command, WorkloadOptions& options);

inline constexpr const char* kLayoutHelp =
    "bvh8 nodes: standard (256 bytes, float planes) or compressed (128 bytes, planes quantised to 8 bits, "
    "conservatively; single-ray tracer only)";
inline constexpr const char* kBatchTraversalHelp =
    "Stream tracer: how canopy traces a sorted batch: packet (16-ray packets, 8 without AVX-512, single rays below "
    "10; the fastest on diffuse rays), single (ray by ray), stream (ray streams)";
inline constexpr const char* kCollapseHelp =
    "How bvh4/bvh8 are made from the binary tree: optimal (Ylitie et al. 2017), greedy (largest area first), or, for "
    "builder lbvh, direct (no binary tree: the wide tree straight from the Morton codes, largest weight first). "
    "Default: direct for lbvh's flat bvh4/bvh8 (its fast build), optimal for every other tree";

inline constexpr const char* kQuietHelp = "No progress line on stderr";

// Adds --memory-limit BYTES (render, bench): the bound on a scene's estimated peak memory, refused at zero or below.
void add_memory_limit_option(CLI::App& command, std::optional<uint64_t>& bytes);

// Every library's threads capped at `threads` while the result lives (0: no cap, nullptr).
inline std::unique_ptr<tbb::global_control> limit_threads(int threads) {
    if (threads <= 0) return nullptr;
    return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(threads));
}

}  // namespace canopy
