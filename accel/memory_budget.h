#pragma once
// A build's peak memory, estimated before anything large is allocated, against the memory the process may use:
// a scene too large for the machine is refused with an error that names both numbers, instead of the kernel
// killing the process half-way through generating or building it.
#include "accel/builder.h"

#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

namespace canopy {

// What is known of a scene before it is built: for a generator spec, before a triangle is generated.
struct SceneSize {
    uint64_t vertices = 0;             // stored positions, over all meshes
    uint64_t triangles = 0;            // stored triangles, over all meshes (each once, however often placed)
    uint64_t instanced_triangles = 0;  // with every placement expanded: what flatten() produces
    uint64_t instances = 1;
};

// One accelerator to be built over the scene.
struct BuildPlan {
    std::string builder = "binned";  // a registered builder's spec, "auto", or "embree"
    int width = 8;                   // of the traversal layout: 2, 4 or 8
    bool two_level = false;          // a two-level or rebraided top level over object trees
};

// Bytes, by what holds them. Every term is an upper bound of its part at the build's peak, and the parts are
// summed although some are freed before others are allocated (PrimRefs before the wide layout): the estimate
// errs towards refusing, never towards being killed.
struct MemoryEstimate {
    uint64_t scene = 0;       // the loaded or generated meshes
    uint64_t flat = 0;        // world-space triangles and materials (flatten), object-space copies (two-level)
    uint64_t references = 0;  // PrimRefs up to the builders' reference caps, and their partition scratch
    uint64_t binary = 0;      // binary BVH nodes and leaf references
    uint64_t layout = 0;      // wide nodes and leaf triangle blocks; two-level pools and top-level entries

    uint64_t total() const { return scene + flat + references + binary + layout; }
    std::string describe() const;  // "61.3 GiB (scene 17.9 GiB, flat 14.9 GiB, ...)"
};

// reference_cap_per_triangle (accel/builder.h) gives the PrimRef slots each builder allocates per triangle.

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

// "1.5 GiB", "12.0 MiB", "512 bytes".
std::string format_bytes(uint64_t bytes);

}  // namespace canopy
