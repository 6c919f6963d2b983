#pragma once
// `canopy render`: one scene, one accelerator, samples accumulated into an EXR (or a heat map of what primary
// rays visit).
#include "experiments/command.h"
#include "scenes/scene.h"

#include <optional>
#include <span>
#include <string>
#include <vector>

namespace canopy {

struct RenderOptions {
    std::string scene, output = "canopy.exr", builder = "binned", start, kernel = "auto", accel = "canopy";
    std::string toplevel = "flat";
    std::string blas_builder;  // two-level top levels: the object trees' builder ("" for --builder)
    int frames_planned = 0;
    bool explain = false;  // --builder auto: print every candidate's costs and the choice
    std::string embree_quality = "medium";
    int spp = 1, threads = 0, bounces = 8;
    std::vector<int> size{1024, 768};
    bool material_albedo = false, heatmap = false, quiet = false;  // quiet: no progress line
    std::string traversal = "robust", intersector = "watertight", collapse;  // collapse: empty for the builder's own
    std::string layout = "standard";     // bvh8 nodes: standard (floats) or compressed (8-bit planes)
    std::string tracer = "single";       // single (one path at a time) or stream (wavefront, sorted ray batches)
    uint32_t stream_paths = 1u << 18;    // stream: paths in flight per batch
    std::string batch_traversal = "packet";  // stream: how batches are traced: single, packet, stream
    std::string stream_batching = "measured";  // stream: each batch's way: measured, wavefront, paths
    std::optional<uint64_t> memory_limit;    // bytes: lowers the memory bound below what the machine has free
    WorkloadOptions workload;
};

void run_render(RenderOptions options);
// `canopy render`, its options and its run.
void register_render(CLI::App& canopy);

}  // namespace canopy
