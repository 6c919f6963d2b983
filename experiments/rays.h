#pragma once
// `canopy rays record`: a frame's rays of a workload written as the ray file `bench --rays` replays
// (renderer/ray_file.h, docs/workloads.md#recorded-rays).
#include "experiments/command.h"

#include <string>
#include <vector>

namespace canopy {

struct RecordOptions {
    std::string scene, output = "rays.npy", builder = "binned", kernel = "auto";
    WorkloadOptions workload;
    std::vector<int> size{1024, 768};
    int bounces = 8;
    int frame = 1;  // the frame index whose random numbers the rays follow (bench's first timed frame)
    bool material_albedo = false;
};

// Records frame o.frame's rays through canopy's o.builder, one pixel after another, and writes them with their hits.
void run_record(const RecordOptions& o);
// `canopy rays` and its subcommand `record`.
void register_rays(CLI::App& canopy);

}  // namespace canopy
