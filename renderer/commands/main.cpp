// The canopy command: its options, and one subcommand per file beside this one.
#include "accel/builder.h"
#include "renderer/commands/bench.h"
#include "renderer/commands/accuracy.h"
#include "renderer/commands/tradeoff.h"
#include "renderer/commands/render.h"
#include "renderer/commands/reproduce.h"
#include "renderer/commands/study.h"
#include "renderer/distributed.h"

#include <CLI/CLI.hpp>
#include <tbb/global_control.h>
#include <malloc.h>
#include <unistd.h>

#include <chrono>
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>

namespace {

using namespace canopy;

constexpr const char* kLayoutHelp =
    "bvh8 nodes: standard (256 bytes, float planes) or compressed (128 bytes, planes quantised to 8 bits, "
    "conservatively; single-ray tracer only)";
constexpr const char* kBatchTraversalHelp =
    "Stream tracer: how canopy traces a sorted batch: packet (16-ray packets, 8 without AVX-512, single rays below "
    "10; the fastest on diffuse rays), single (ray by ray), stream (ray streams)";

constexpr const char* kCollapseHelp =
    "How bvh4/bvh8 are made from the binary tree: optimal (Ylitie et al. 2017), greedy (largest area first), or, for "
    "builder lbvh, direct (no binary tree: the wide tree straight from the Morton codes, largest weight first). "
    "Default: direct for lbvh's flat bvh4/bvh8 (its fast build), optimal for every other tree";
constexpr const char* kMemoryLimitHelp =
    "Refuse scenes whose estimated peak memory (scene, PrimRefs, trees) exceeds these bytes (suffixes k, M, G: "
    "powers of 1024); the bound is otherwise the memory the machine and its cgroup have available";

// Freed memory stays in the process for the next build instead of going back to the kernel: glibc otherwise maps
// large arrays afresh for every build and unmaps them when freed, and on this project's VM the page faults of
// touching them again cost more than the work (a 2-million-triangle collapse: 0.7 s of faults for 0.1 s of
// writing). Builds after the first reuse the memory; the bench reports the fastest of several builds.
void keep_freed_memory() {
    constexpr int kLargest = 1 << 30;  // allocations up to 1 GiB come from the heap, which is never trimmed below it
    mallopt(M_MMAP_THRESHOLD, kLargest);
    mallopt(M_TRIM_THRESHOLD, kLargest);
}

// `text` as a POSIX shell reads it back: single-quoted when it holds anything but plain characters.
std::string shell_quoted(const std::string& text) {
    const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("_./,=:@%+-", c);
    });
    if (plain) return text;
    std::string quoted = "'";
    for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return quoted + "'";
}

// The flags from before builders took parameters, `--esc-sa-max 8x,auto` and `--sbvh-alpha 1e-5`: each plain
// `builder` in the builder lists becomes one spec per value ("esc:sa_max=8x", a row each).
void apply_param_alias(const std::string& flag, const std::string& builder, const std::string& key,
                       const std::vector<std::string>& values, BenchOptions& b) {
    bool used = false;
    for (std::vector<std::string>* list : {&b.builders, &b.blas_builders}) {
        std::vector<std::string> specs;
        for (const std::string& spec : *list) {
            if (spec != builder) {
                specs.push_back(spec);
                continue;
            }
            for (const std::string& value : values) specs.push_back(builder + ":" + key + "=" + value);
            used = true;
        }
        *list = specs;
    }
    if (!used) throw std::invalid_argument(flag + ": only with --builder " + builder);
}

}  // namespace

int main(int argc, char** argv) {
    distributed::Session session(argc, argv);  // a job of ranks under mpirun or srun, else this process alone
    keep_freed_memory();
    CLI::App app{"canopy: a CPU ray tracer with pluggable BVH builders, measured against Embree"};
    app.require_subcommand(1);
    int threads = 0;

    RenderOptions r;
    CLI::App* render = app.add_subcommand("render", "Render a scene to an EXR");
    render->add_option("scene", r.scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S (default: embedded scene)");
    render->add_option("-o,--output", r.output, "Output EXR")->capture_default_str();
    render->add_option("--spp", r.spp, "Samples (frames) per pixel")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    render->add_option("--size", r.size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    render->add_option("--builder", r.builder, "Builder (of a BVH, or kdtree: a kd-tree): " + builder_names())->capture_default_str();
    render->add_option("--start", r.start, "Optimisers: builder of the start tree (default: the optimiser's own)");
    render->add_option("--toplevel", r.toplevel, "flat, two-level or rebraid")
        ->check(CLI::IsMember({"flat", "two-level", "rebraid"}))->capture_default_str();
    render->add_option("--blas-builder", r.blas_builder, "Two-level top levels: builder of every object BVH (default: --builder)");
    render->add_option("--frames-planned", r.frames_planned, "Frames that --builder auto plans for (default: --spp)")
        ->check(CLI::Range(1, 1 << 24));
    render->add_flag("--explain", r.explain, "--builder auto: every candidate's predicted or measured build and frame time, and the choice");
    render->add_option("--kernel", r.kernel, "Traversal kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    render->add_option("--accel", r.accel, "canopy or embree")->check(CLI::IsMember({"canopy", "embree"}))->capture_default_str();
    render->add_option("--embree-quality", r.embree_quality, "low, medium or high")->capture_default_str();
    render->add_option("--bounces", r.bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    render->add_option("--threads", threads, "Threads for every library (0: all)")->check(CLI::Range(0, 4096));
    render->add_flag("--materials", r.material_albedo,
                     "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light (protocol: 0.8 grey, sky only)");
    render->add_flag("--heatmap", r.heatmap,
                     "Instead of rendering, write what primary rays visit: EXR channels inner, leaves, triangles, and a false-colour PNG beside it");
    render->add_option("--traversal", r.traversal, "robust (padded slab test, Ize 2013) or fast")
        ->check(CLI::IsMember({"robust", "fast"}))->capture_default_str();
    render->add_option("--intersector", r.intersector, "watertight (Woop et al. 2013) or moller (Möller–Trumbore, fast)")
        ->check(CLI::IsMember({"watertight", "moller"}))->capture_default_str();
    render->add_option("--tracer", r.tracer, "single (one path at a time) or stream (each bounce's rays as one sorted batch)")
        ->check(CLI::IsMember({"single", "stream"}))->capture_default_str();
    render->add_option("--stream-paths", r.stream_paths, "Stream tracer: paths in flight per batch")
        ->check(CLI::Range(1, 1 << 24))->capture_default_str();
    render->add_option("--batch-traversal", r.batch_traversal, kBatchTraversalHelp)
        ->check(CLI::IsMember({"single", "packet", "stream"}))->capture_default_str();
    render->add_option("--memory-limit", r.memory_limit, kMemoryLimitHelp)->transform(CLI::AsSizeValue(false));
    render->add_option("--collapse", r.collapse, kCollapseHelp)->check(CLI::IsMember({"optimal", "greedy", "direct"}));
    render->add_option("--layout", r.layout, kLayoutHelp)->check(CLI::IsMember({"standard", "compressed"}))->capture_default_str();

    BenchOptions b;
    std::vector<std::string> accels;
    std::vector<std::string> qualities{"medium"};
    CLI::App* bench = app.add_subcommand("bench", "Benchmark builders and kernels against Embree (BENCHMARK.md)");
    std::vector<std::string> bench_scenes;
    bench->add_option("scenes", bench_scenes, "Scenes, each benched in turn: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")
        ->required();
    bench->add_option("--builder", b.builders, "Builders: " + builder_names())->delimiter(',')->capture_default_str();
    bench->add_option("--start", b.start, "Optimisers among the builders: builder of their start tree");
    bench->add_option("--toplevel", b.toplevels, "Top levels: flat, two-level (object BVHs under a BVH over instances), rebraid (Benthin 2017)")
        ->delimiter(',')->check(CLI::IsMember({"flat", "two-level", "rebraid"}))->capture_default_str();
    CLI::Option* rebraid_option = bench->add_option("--rebraid-threshold", b.rebraid_thresholds,
                      "Rebraid rows: open BRefs wider than this share of their segment's extent, 0 to 1 (sec. 4.2); a row each")
        ->delimiter(',')->check(CLI::Range(0.0, 1.0))->capture_default_str();
    std::vector<std::string> esc_area_limits, sbvh_alpha_values;
    CLI::Option* esc_option = bench->add_option("--esc-sa-max", esc_area_limits,
                      "esc rows, a row each: --builder esc:sa_max=VALUE for each value")->delimiter(',');
    CLI::Option* alpha_option = bench->add_option("--sbvh-alpha", sbvh_alpha_values,
                      "sbvh rows, a row each: --builder sbvh:alpha=VALUE for each value")->delimiter(',');
    bench->add_option("--blas-builder", b.blas_builders,
                      "Two-level top levels: builders of the object BVHs, a row each (default: the --builder list)")
        ->delimiter(',');
    bench->add_option("--frames-planned", b.frames_planned, "Frames that --builder auto plans time to image for (a row each)")
        ->delimiter(',')->check(CLI::Range(1, 1 << 24))->capture_default_str();
    bench->add_flag("--explain", b.explain, "--builder auto: every candidate's predicted or measured build and frame time, and the choice");
    bench->add_option("--kernel", b.kernels, "Kernels: auto (widest), bvh2, bvh4, bvh8")->delimiter(',')->capture_default_str();
    bench->add_option("--accel", accels, "Reference accelerators in the same run: embree")->delimiter(',')
        ->check(CLI::IsMember({"embree"}));
    bench->add_option("--embree-quality", qualities, "Embree qualities: low, medium, high")->delimiter(',')
        ->check(CLI::IsMember({"low", "medium", "high"}))->capture_default_str();
    bench->add_option("--builds", b.builds, "Builds (minimum reported)")->check(CLI::Range(1, 10000))->capture_default_str();
    bench->add_option("--frames", b.frames, "Timed frames after one warm-up")->check(CLI::Range(1, 10000))->capture_default_str();
    bench->add_option("--bounces", b.bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    bench->add_option("--json", b.json_path, "Write results as JSON");
    bench->add_flag("!--no-epo", b.epo, "Skip EPO in the report (minutes on millions of triangles)");
    bench->add_option("--threads", b.threads, "Threads for every library (0: all); a list runs the whole bench once per count")
        ->delimiter(',')->check(CLI::Range(0, 4096))->capture_default_str();
    bench->add_flag("--materials", b.material_albedo, "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light");
    bench->add_option("--traversal", b.traversals, "Traversal modes: robust, fast")->delimiter(',')
        ->check(CLI::IsMember({"robust", "fast"}))->capture_default_str();
    bench->add_option("--intersector", b.intersectors, "Intersectors: watertight, moller (Möller–Trumbore)")->delimiter(',')
        ->check(CLI::IsMember({"watertight", "moller"}))->capture_default_str();
    bench->add_option("--collapse", b.collapses, std::string(kCollapseHelp) + "; a row each")
        ->delimiter(',')->check(CLI::IsMember({"optimal", "greedy", "direct"}));
    bench->add_option("--layout", b.layouts, std::string(kLayoutHelp) + "; a row each")
        ->delimiter(',')->check(CLI::IsMember({"standard", "compressed"}))->capture_default_str();
    bench->add_option("--tracer", b.tracers, "Tracers: single (one path at a time), stream (each bounce's rays as one sorted batch)")
        ->delimiter(',')->check(CLI::IsMember({"single", "stream"}))->capture_default_str();
    bench->add_option("--stream-paths", b.stream_paths, "Stream tracer: paths in flight per batch")
        ->check(CLI::Range(1, 1 << 24))->capture_default_str();
    bench->add_option("--batch-traversal", b.batch_traversals, std::string(kBatchTraversalHelp) + "; a stream row each")
        ->delimiter(',')->check(CLI::IsMember({"single", "packet", "stream"}))->capture_default_str();
    bench->add_option("--embree-stream", b.embree_streams,
                      "Stream tracer: Embree's batch interface, a stream row each: 1m (rtcIntersect1M, incoherent), 16 (rtcIntersect16 packets)")
        ->delimiter(',')->check(CLI::IsMember({"1m", "16"}))->capture_default_str();
    std::string dynamic;
    CLI::Option* dynamic_option =
        bench->add_option("--dynamic", dynamic,
                          "Dynamic-in-static (Benthin 2017, Table 3): this object moves every frame; each frame's rebuild "
                          "and render are timed. An object or mesh name, a placement index, or auto (alone: the largest "
                          "object spanning at most a quarter of the scene); --builds is then 1")
            ->expected(0, 1)->default_str("auto");
    bench->add_option("--memory-limit", b.memory_limit, kMemoryLimitHelp)->transform(CLI::AsSizeValue(false));
    std::vector<int> bench_size{1024, 768};
    bench->add_option("--size", bench_size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();

    StudyOptions st;
    std::vector<int> study_size{256, 192};
    CLI::App* study = app.add_subcommand("study", "SAH, EPO and LCV against measured ns/ray for every builder (Aila et al. 2013)");
    study->add_option("scenes", st.scenes, "Scenes: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    study->add_option("--builder", st.builders, "Builders (default: every BVH builder): " + builder_names())->delimiter(',');
    study->add_option("--size", study_size, "Width and height of the frame whose diffuse rays are timed")
        ->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    study->add_option("--repeats", st.repeats, "Timing passes per tree (fastest kept)")->check(CLI::Range(1, 100))->capture_default_str();
    study->add_option("--json", st.json_path, "Write results as JSON");
    study->add_flag("--rotate", st.rotate, "Also each builder on the scene and rays rotated 45 degrees about (1, 1, 1) (sec. 4.4)");
    study->add_flag("--permute-nodes", st.permute_nodes, "Also each SIMD tree with its nodes shuffled in memory (sec. 6)");
    study->add_option("--permute-seed", st.permute_seed, "Seed of --permute-nodes' shuffle")->capture_default_str();
    study->add_option("--plot", st.plot_path, "Write a PNG: predicted (eq. 7) against measured SIMD ns/ray, a panel per scene");

    TradeoffOptions tr;
    std::vector<std::string> tradeoff_accels;
    std::vector<int> tradeoff_size{tr.width, tr.height};
    CLI::App* tradeoff = app.add_subcommand("tradeoff", "Time to image against RMSE per builder, against a converged reference");
    tradeoff->add_option("scene", tr.scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    tradeoff->add_option("--builder", tr.builders, "Builders: " + builder_names())->delimiter(',')->capture_default_str();
    tradeoff->add_option("--kernel", tr.kernel, "Kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    tradeoff->add_option("--accel", tradeoff_accels, "Also Embree, at the --embree-quality levels")->delimiter(',')
        ->check(CLI::IsMember({"embree"}));
    tradeoff->add_option("--embree-quality", tr.embree_qualities, "Embree qualities: low, medium, high")->delimiter(',')
        ->check(CLI::IsMember({"low", "medium", "high"}));
    tradeoff->add_option("--seconds", tr.seconds, "Wall time per builder, build included")->check(CLI::Range(0.001, 1e6))->capture_default_str();
    tradeoff->add_option("--max-frames", tr.max_frames, "Frames per builder at most")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    tradeoff->add_option("--reference-spp", tr.reference_spp, "Samples of the cached reference")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    tradeoff->add_option("--size", tradeoff_size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    tradeoff->add_option("--bounces", tr.bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    tradeoff->add_flag("--materials", tr.material_albedo, "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light");
    tradeoff->add_option("-o,--output", tr.output, "Output stem: STEM.json, STEM.csv, STEM.png, cached reference beside")->capture_default_str();
    tradeoff->add_option("--threads", threads, "Threads for every library (0: all)")->check(CLI::Range(0, 4096));

    AccuracyOptions ac;
    CLI::App* accuracy = app.add_subcommand("accuracy", "Leaks and hit-distance error of every intersector and traversal mode, scaled and moved");
    accuracy->add_option("--builder", ac.builder, "Builder (of a BVH, or kdtree: a kd-tree): " + builder_names())->capture_default_str();
    accuracy->add_option("--kernel", ac.kernel, "Kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    accuracy->add_option("--rays", ac.rays, "Rays per case and mode")->check(CLI::Range(1, 100000000))->capture_default_str();
    accuracy->add_option("--json", ac.json_path, "Write the rows as JSON");
    accuracy->add_option("--plot", ac.plot_path, "Write a PNG: distance error against coordinate magnitude");
    accuracy->add_option("--threads", threads, "Threads (0: all)")->check(CLI::Range(0, 4096));

    ReproduceOptions rp;
    CLI::App* reproduce = app.add_subcommand("reproduce", "A paper's tables measured again, written to docs/papers/PAPER.md beside the paper's figures");
    std::string reproduce_papers;
    for (const std::string& name : reproducible_papers()) reproduce_papers += name + ", ";
    reproduce->add_option("paper", rp.paper, "Paper: " + reproduce_papers + "or all")->required();
    reproduce->add_flag("--quick", rp.quick, "Smaller scenes and images, one build and one frame: minutes");
    reproduce->add_option("--out", rp.out_dir, "Folder of PAPER.md and PAPER.json")->capture_default_str();
    reproduce->add_option("--scenes-dir", rp.scenes_dir, "Folder of the shared scenes")->capture_default_str();
    reproduce->add_option("--scenes", rp.scenes, "Your scenes instead of the paper's (no paper figures beside them)")->delimiter(',');
    for (int i = 1; i < argc; ++i) rp.command += (rp.command.empty() ? "canopy " : " ") + shell_quoted(argv[i]);

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {  // every rank parses the same arguments: one says what is wrong
        return distributed::is_root() ? app.exit(e) : e.get_exit_code();
    }
    std::optional<tbb::global_control> limit;
    if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(threads));
    try {
        if (*render) {
            r.threads = threads;
            run_render(r);
        } else if (*reproduce) {
            run_reproduce(rp);
        } else if (*accuracy) {
            if (distributed::is_root()) run_accuracy(ac);  // not split: under a job, rank 0's alone
        } else if (*tradeoff) {
            tr.width = tradeoff_size[0], tr.height = tradeoff_size[1];
            tr.builders = join_builder_specs(tr.builders);
            if (tradeoff_accels.empty()) tr.embree_qualities.clear();
            else if (tr.embree_qualities.empty()) tr.embree_qualities = {"medium"};
            run_tradeoff(tr);
        } else if (*study) {
            distributed::checked([&] {
                st.builders = join_builder_specs(st.builders);
                for (const std::string& b : st.builders) check_builder_name(b);  // unknown names fail before any work
            });
            st.width = study_size[0], st.height = study_size[1];
            run_study(st);
        } else {
            b.width = bench_size[0], b.height = bench_size[1];
            if (!accels.empty()) b.embree_qualities = qualities;
            if (dynamic_option->count()) b.dynamic = dynamic;
            distributed::checked([&] {
                if (rebraid_option->count() && std::find(b.toplevels.begin(), b.toplevels.end(), "rebraid") == b.toplevels.end())
                    throw std::invalid_argument("--rebraid-threshold: only with --toplevel rebraid");
                b.builders = join_builder_specs(b.builders), b.blas_builders = join_builder_specs(b.blas_builders);
                if (esc_option->count()) apply_param_alias("--esc-sa-max", "esc", "sa_max", esc_area_limits, b);
                if (alpha_option->count()) apply_param_alias("--sbvh-alpha", "sbvh", "alpha", sbvh_alpha_values, b);
                for (const std::string& blas : b.blas_builders) check_blas_builder(blas, b.toplevels);
                for (const std::string& builder : b.builders)
                    if (builder != "auto") check_builder_name(builder);
            });
            run_bench(bench_scenes, b);
        }
    } catch (const distributed::JobError& e) {  // known to every rank: rank 0 says it
        if (distributed::is_root()) std::fprintf(stderr, "canopy: error: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "canopy: error: %s%s\n", e.what(), distributed::where().c_str());
        // Other ranks may be waiting for this one: end them too.
        if (distributed::ranks() > 1) distributed::abort_job(1);
        return 1;
    }
    return 0;
}
