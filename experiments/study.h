#pragma once
// `canopy study`: the correlation study of Aila, Karras and Laine 2013 (Tables 1 and 2) for canopy's builders.
#include "experiments/command.h"
#include "renderer/frames.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <optional>
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

// A builder's tree in one scene: its metrics and measured times.
struct StudyRow {
    std::string builder;
    std::string host;  // the machine that measured the row
    double scalar_sah = 0, scalar_epo = 0, scalar_ns = 0;       // binary tree, scalar kernel
    double sah = 0, epo = 0, lcv = 0, simd_ns = 0;              // the widest kernel's tree (binary, before collapse)
    double wide_sah = 0, wide_epo = 0;                          // the same tree collapsed to the kernel's width
    // --rotate (sec. 4.4): the widest kernel's tree of the rotated scene, traced with the rotated rays; NaN if not run.
    double rotated_sah = std::nan(""), rotated_epo = std::nan(""), rotated_lcv = std::nan(""), rotated_ns = std::nan("");
    // --permute-nodes (sec. 6): the same SIMD tree with its nodes shuffled in memory, and the original timed
    // alternately with it.
    double permuted_ns = std::nan(""), unpermuted_ns = std::nan("");
};

// Weights of eq. 6 (beta 0) or eq. 7 and the correlation they reach; none when the costs do not vary.
struct StudyFit {
    double alpha = 0, beta = 0;
    std::optional<double> correlation;
};

// One scene's rows and how well each cost model predicts their times over its BVH rows.
struct StudyScene {
    std::string scene;
    std::vector<StudyRow> rows;
    std::optional<double> scalar_sah, simd_sah;  // SAH alone
    StudyFit scalar_epo, simd_epo, simd_lcv;    // eq. 6 (scalar and SIMD), eq. 7 (SIMD)
};

struct StudyResult {
    std::vector<StudyScene> scenes;
    StudyFit fixed_scalar, fixed_simd;  // Table 2's one alpha (and beta) for all scenes: eq. 6 scalar, eq. 7 SIMD
};

void run_study(const StudyOptions& options);
// run_study's measurement and printed tables; the result on rank 0, elsewhere empty.
StudyResult measure_study(const StudyOptions& options);
// The result as --json writes it.
nlohmann::json study_json(const StudyResult& result);
// `canopy study`, its options and its run.
void register_study(CLI::App& canopy);

// Eq. 5 of the paper, Pearson's correlation; none when either side does not vary.
std::optional<double> pearson(const std::vector<double>& x, const std::vector<double>& y);

// Eq. 4 of the paper: the standard deviation of the number of leaves each ray visits (closest hit).
double leaf_count_variability(const Accelerator& accel, const std::vector<Ray>& rays);

}  // namespace canopy
