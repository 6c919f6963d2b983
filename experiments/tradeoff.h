#pragma once
#include "experiments/command.h"
#include <string>
#include <vector>

namespace canopy {

struct TradeoffOptions {
    std::string scene;
    std::vector<std::string> builders{"lbvh", "binned", "sweep"};
    std::vector<std::string> embree_qualities;  // Embree rows in the same run, if any
    std::string kernel = "auto";
    double seconds = 20;        // each builder's clock runs until this much wall time (build included)
    int max_frames = 1024;
    int reference_spp = 1024;   // samples of the converged reference (rendered once, cached as EXR)
    int width = 512, height = 384;
    int bounces = 8;
    bool material_albedo = false;
    // A curve per accelerator and workload. Several workloads must converge to one image (diffuse and nee with the
    // scene's emitters as lights, under --materials); the reference is then nee's.
    std::vector<std::string> workloads{"diffuse"};
    WorkloadOptions workload;  // ao's rays and length
    std::string output = "tradeoff";  // writes OUTPUT.json, OUTPUT.csv, OUTPUT.png and the cached reference beside them
};

// Time to image against image error: per builder, a clock from the start of the build through every accumulated
// frame, with the RMSE of the running average against the reference after each frame (the RMSE itself is not
// timed). Prints the time each builder needs to reach a few error levels; writes JSON, CSV and a log-log plot.
void run_tradeoff(const TradeoffOptions& options);

// `canopy tradeoff`, its options and its run.
void register_tradeoff(CLI::App& canopy);

}  // namespace canopy
