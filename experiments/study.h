#pragma once
// `canopy study`: the correlation study of Aila, Karras and Laine 2013 (Tables 1 and 2) for canopy's builders.
#include "renderer/frames.h"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace canopy {

struct StudyOptions {
    std::vector<std::string> scenes;
    std::vector<std::string> builders;  // empty: every registered builder
    int width = 256, height = 192;      // resolution of the frame whose diffuse rays are timed
    int repeats = 3;                    // timings per tree; the fastest is kept
    std::string json_path, plot_path;
    bool rotate = false;         // also the scene and rays turned 45 degrees about (1, 1, 1) (sec. 4.4)
    bool permute_nodes = false;  // also each SIMD tree with its nodes shuffled in memory (sec. 6)
    uint64_t permute_seed = 1;
};

void run_study(const StudyOptions& options);
// run_study's measurement and printed tables; on rank 0 also its JSON (as --json writes it), elsewhere null.
nlohmann::json measure_study(const StudyOptions& options);

// Eq. 4 of the paper: the standard deviation of the number of leaves each ray visits (closest hit).
double leaf_count_variability(const Accelerator& accel, const std::vector<Ray>& rays);

}  // namespace canopy
