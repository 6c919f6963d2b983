#pragma once
#include "accel/builder.h"
#include "accel/memory_budget.h"
#include "accel/two_level.h"
#include "experiments/command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace canopy {

struct BenchOptions {
    std::string scene;  // the scene of run_bench(options); run_bench(scenes, options) sets it per scene
    std::vector<std::string> builders{"binned"};  // specs with parameters: "sbvh:alpha=1e-5" (accel/builder.h)
    std::string start;  // start tree of the optimisers among the builders ("" for each one's default)
    std::vector<std::string> kernels{"auto"};
    std::vector<std::string> toplevels{"flat"};  // flat, two-level, rebraid
    std::vector<float> rebraid_thresholds{TwoLevelSettings().open_extent};  // a rebraid row each (sec. 4.2, Fig. 4)
    std::vector<std::string> blas_builders;  // object BVH builders of the two-level rows; empty: `builders`
    std::vector<std::string> traversals{"robust"};      // robust, fast
    std::vector<std::string> intersectors{"watertight"};  // watertight, moller
    std::vector<std::string> collapses{""};  // optimal, greedy, direct; "": the builder's own
    std::vector<std::string> layouts{"standard"};         // standard, compressed (bvh8)
    std::vector<std::string> embree_qualities;  // empty: no Embree rows
    std::vector<std::string> tracers{"single"};  // single, stream: a row each per accelerator, built once
    uint32_t stream_paths = 1u << 18;            // stream: paths in flight per batch
    std::vector<std::string> embree_streams{"1m"};  // stream: Embree's batch interface (a row each): 1m (rtcIntersect1M), 16 (packets)
    std::vector<std::string> batch_traversals{"packet"};  // stream: how canopy traces a batch (a row each): single, packet, stream
    std::vector<std::string> stream_batchings{"measured"};  // stream: each batch's way (a row each): measured, wavefront, paths
    int builds = 20;
    int frames = 10;
    std::vector<int> frames_planned{16};  // `--builder auto` rows: one per value, each planning for that many frames
    bool explain = false;                 // `--builder auto` rows: print every candidate's costs and the choice
    std::vector<int> threads{0};  // a whole run per count, each with its own table and rows (0: all threads)
    int width = 1024, height = 768;
    int bounces = 8;
    bool material_albedo = false;
    WorkloadOptions workload;  // the rays every row's frames trace
    std::string rays_path;     // recorded rays (`canopy rays record`) replayed instead of frames; empty: frames
    std::string json_path;
    bool epo = true;  // EPO in the report (exact, slow on millions of triangles)
    // Dynamic-in-static (renderer/dynamic.h): the object that moves every frame ("auto", an index or a name);
    // none for a static scene. Rebuilds are then timed per frame instead of --builds builds.
    std::optional<std::string> dynamic;
    std::optional<uint64_t> memory_limit;  // bytes: lowers the memory bound below what the machine has free
};

// The builds a bench keeps until its report, one per row as it makes them: the memory bound plans for all of them.
std::vector<BuildPlan> build_plans(const BenchOptions& o);

// Runs ../shared/BENCHMARK.md's measurement for every requested accelerator in one process,
// alternating between them build by build and frame by frame; prints the table, writes JSON.
void run_bench(const BenchOptions& options);
// The same for each scene in turn; under a job of several ranks, each scene on one rank (per_scene.h). The JSON
// is the one scene's, or {"scenes": [each scene's]}; every row names the host that measured it.
void run_bench(const std::vector<std::string>& scenes, const BenchOptions& options);
// A row of a bench's results, for commands that read them (the papers): NaN where the row has no such figure.
struct BenchRow {
    std::string accel;    // canopy or embree
    std::string builder;  // canopy's: its builder, "two-level/binned" for a top level over object trees; else empty
    std::string quality;  // Embree's: low, medium or high; else empty
    int threads = 0;      // static benches: the --threads value of the row (0: all)
    std::optional<double> rebraid_threshold;  // rebraid rows
    BuilderParams builder_params;              // canopy's rows of a named builder: each parameter's value
    static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
    double build_ms_min = kNone, frame_ms_mean = kNone;  // dynamic benches: the first build, the render's mean
    double sah = kNone, layout_sah = kNone, refs_per_tri = kNone, split_ms = kNone, bytes = kNone;
    double top_level_ms = kNone, brefs = kNone, inner_per_ray = kNone, triangles_per_ray = kNone;
    double rebuild_ms_mean = kNone, total_ms_mean = kNone;  // dynamic benches: per frame, after the object moved

    // "embree medium", or canopy's builder.
    std::string name() const { return accel == "embree" ? "embree " + quality : builder; }
};

// One scene's bench: its rows, and its JSON as --json writes it.
struct BenchScene {
    std::string scene;
    std::vector<BenchRow> rows;
    nlohmann::json json;
};

// run_bench's measurement and printed tables without the JSON file: on rank 0, each scene's results in the
// scenes' order (other ranks: none). Collective.
std::vector<BenchScene> measure_bench(const std::vector<std::string>& scenes, const BenchOptions& options);
// The scenes' JSON, an array.
nlohmann::json bench_json(const std::vector<BenchScene>& scenes);

// `canopy bench`, its options and its run.
void register_bench(CLI::App& canopy);

}  // namespace canopy
