#pragma once
// A build's peak memory, estimated before anything large is allocated, against the memory the process may use:
// a scene too large for the machine is refused with an error that names both numbers, instead of the kernel
// killing the process half-way through generating or building it.
#include "scenes/scene.h"

#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy {

// One accelerator to be built over the scene.
struct BuildPlan {
    std::string builder = "binned";  // a registered builder's spec, "auto", or "embree"
    int width = 8;                   // of the traversal layout: 2, 4 or 8
    bool two_level = false;          // a two-level or rebraided top level over object trees
    // PrimRef slots the builder allocates per triangle at most: filled from its registry entry by make_build_plan
    // (accel/builder.h), as this file is also built without the builders.
    double reference_cap = 1.0;
    std::vector<BuildPlan> auto_candidates;  // for "auto": the builds it may choose between
};

// Bytes, by what holds them, at the build's peak as the builders' leaf policies and the layouts' bytes per triangle
// make it: an expected figure (docs/results.md, "Memory estimate", compares it with measured peaks), not a worst case.
// Each row's trees stay while later rows build; a build's scratch is counted where it outlives the trees' growth.
struct MemoryEstimate {
    uint64_t process = 0;     // what the process holds before loading: code, libraries, thread pools (the caller's)
    uint64_t scene = 0;       // the loaded or generated meshes
    uint64_t flat = 0;        // world-space triangles and materials (flatten), object-space copies (two-level),
                              // Embree's vertex and index buffers
    uint64_t references = 0;  // PrimRefs up to the builders' reference caps and their partition scratch, beyond the
                              // layout written after they are freed; Embree's build scratch
    uint64_t binary = 0;      // binary BVH nodes and leaf references
    uint64_t layout = 0;      // wide nodes and leaf triangle blocks; two-level pools and top-level entries; Embree's BVH
    uint64_t frames = 0;      // images and the stream tracer's batches (the caller's)

    uint64_t total() const { return process + scene + flat + references + binary + layout + frames; }
    std::string describe() const;  // "61.3 GiB (scene 17.9 GiB, flat 14.9 GiB, ...)"
};

// The scene counted once; each plan's trees (binary BVH, layout) summed, as the bench keeps every row's accelerator
// alive; the largest plan's PrimRefs and build scratch, as rows build one after another and free them.
MemoryEstimate estimate_memory(const SceneSize& size, std::span<const BuildPlan> plans);

struct MemoryAvailable {
    uint64_t bytes = 0;
    std::string source;  // what set it: "--memory-limit", "MemAvailable in /proc/meminfo", a cgroup file
};

// The least of: MemAvailable (plus what this process already holds), the cgroup's limit less its use (v2 or v1),
// and `limit` when given (it lowers the bound, never raises it).
MemoryAvailable available_memory(std::optional<uint64_t> limit);

struct MemoryError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// Throws MemoryError naming `what`, the estimate and the memory available when the estimate does not fit.
void require_memory(const std::string& what, const MemoryEstimate& estimate, const MemoryAvailable& available);

// This process's resident memory now (/proc/self/statm).
uint64_t resident_bytes();

// "1.5 GiB", "12.0 MiB", "512 bytes".
std::string format_bytes(uint64_t bytes);

}  // namespace canopy
