#include "experiments/bench.h"
#include "base/output_path.h"
#include "experiments/embree_accelerator.h"

#include "accel/builder.h"
#include "accel/builders/early_split_clipping.h"
#include "kernels/dispatch.h"
#include "renderer/frames.h"
#include "renderer/distributed.h"
#include "engine/options.h"
#include "experiments/command.h"
#include "experiments/dynamic.h"
#include "experiments/per_scene.h"
#include "renderer/progress.h"
#include "renderer/wavefront.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <tuple>

namespace canopy {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double mean(const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0) / double(v.size()); }

struct Entry {
    std::shared_ptr<Accelerator> accel;  // shared by the rows of its tracers, built once
    TracerKind tracer = TracerKind::Single;
    std::string batch;  // canopy's stream rows: the batch traversal, when the bench compares several
    FrameSettings settings;  // the frame this row renders
    std::shared_ptr<StreamStats> stream = std::make_shared<StreamStats>();  // the stream tracer's sorting and memory
    std::vector<double> build_ms, frame_ms;
    std::vector<double> rebuild_ms;  // dynamic scenes: per timed frame, after the object moved
    uint64_t rays = 0;
    double image_mean = 0;
    AcceleratorReport report;  // taken once after the last build: EPO is not free
    int threads = 0;         // the --threads value the row ran under (0: all)
    std::string thread_tag;  // " 2 threads" in labels when the bench compares thread counts, else empty
    std::optional<TraversalCounts> visits;  // canopy: the first timed frame's rays through the counting kernel
    uint64_t counted_rays = 0;
    std::optional<float> rebraid_threshold;  // canopy's rebraid rows
    nlohmann::json builder_params;           // canopy's rows of a named builder: each parameter's value
    // --rays: the answers that differ from the recorded ones (hit or not; a closest hit on another triangle at
    // another distance), closest hits on another triangle at the recorded distance (ties), and closest hits on the
    // recorded triangle at a distance of other bits.
    uint64_t answers_differ = 0, ties = 0, t_bits_differ = 0;

    double build_min() const { return *std::min_element(build_ms.begin(), build_ms.end()); }
    double frame_mean() const { return mean(frame_ms); }
    double rebuild_mean() const { return mean(rebuild_ms); }
    double total_mean() const { return rebuild_mean() + frame_mean(); }  // Table 3's build + render
    double rays_per_frame() const { return double(rays) / double(frame_ms.size()); }
    std::optional<double> per_ray(uint64_t TraversalCounts::*field) const {
        if (!visits || counted_rays == 0) return std::nullopt;
        return double((*visits).*field) / double(counted_rays);
    }
    std::string label() const {
        const std::string suffix = tracer == TracerKind::Single ? "" : batch.empty() ? " stream" : " stream/" + batch;
        if (accel->library() == "embree") return "embree " + accel->quality() + suffix + thread_tag;
        const std::string chosen = accel->chosen();
        const std::string planned = accel->frames_planned() ? "@" + std::to_string(accel->frames_planned()) : "";
        return accel->builder() + planned + (chosen.empty() ? "" : "(" + chosen + ")") + " " + accel->kernel() + suffix +
               thread_tag;
    }
    // The stream tracer's share of the timed frames spent sorting rays (all threads' time over threads x frames).
    double sort_share() const {
        const double threads = double(working_threads());
        return double(stream->sort_ns.load()) / 1e6 / threads / std::accumulate(frame_ms.begin(), frame_ms.end(), 0.0);
    }
};

TracerKind parse_tracer(const std::string& name) {
    if (name == "single") return TracerKind::Single;
    if (name == "stream") return TracerKind::Stream;
    throw std::invalid_argument("unknown --tracer '" + name + "' (known: single, stream)");
}

const char* tracer_name(TracerKind tracer) { return tracer == TracerKind::Stream ? "stream" : "single"; }

// Every accelerator once per tracer (canopy's stream rows once per batch traversal), the first row building it, the
// others sharing it.
std::vector<Entry> rows_per_tracer(std::vector<Entry> accelerators, const BenchOptions& o) {
    std::vector<Entry> rows;
    for (Entry& a : accelerators)
        for (const std::string& t : o.tracers) {
            const TracerKind tracer = parse_tracer(t);
            const bool canopy = a.accel->library() == "canopy";
            const std::vector<std::string>& ways = canopy ? o.batch_traversals : o.embree_streams;
            const bool stream = tracer == TracerKind::Stream;
            for (const std::string& batch : stream ? ways : std::vector<std::string>{""})
                for (const std::string& batching : stream ? o.stream_batchings : std::vector<std::string>{""}) {
                    Entry row;
                    row.accel = a.accel;
                    row.rebraid_threshold = a.rebraid_threshold, row.builder_params = a.builder_params;
                    row.tracer = tracer;
                    row.batch = ways.size() > 1 ? batch : "";
                    if (o.stream_batchings.size() > 1 && stream) row.batch += (row.batch.empty() ? "" : "/") + batching;
                    if (canopy && !batch.empty()) row.settings.batch_traversal = parse_batch_traversal(batch);
                    if (stream) row.settings.stream_batching = parse_stream_batching(batching);
                    row.settings.embree_packets = !canopy && batch == "16";
                    rows.push_back(std::move(row));
                }
        }
    return rows;
}

// The first row of each accelerator builds it; the rows of its other tracers report those builds.
bool builds_its_accelerator(const std::vector<Entry>& entries, size_t i) {
    return i == 0 || entries[i - 1].accel != entries[i].accel;
}

// --start applies to the optimisers in a bench; plain builders in the same run ignore it.
std::string optimiser_start(const std::string& builder, const std::string& start) {
    return is_bvh_builder(spec_name(builder)) && find_builder(spec_name(builder)).optimiser() ? start : "";
}

// "2 threads", "1 thread" or "all threads" (0).
std::string threads_text(int threads) {
    if (threads == 0) return "all threads";
    return std::to_string(threads) + (threads == 1 ? " thread" : " threads");
}

// The opening thresholds of a top level's rows: rebraid's list, one row for the others.
std::vector<float> rebraid_thresholds_of(const std::string& toplevel, const BenchOptions& o) {
    return toplevel == "rebraid" ? o.rebraid_thresholds : std::vector<float>{TwoLevelSettings{}.open_extent};
}

// Every parameter of a BVH builder's spec with its value, the defaults included; {} for other families.
nlohmann::json builder_params_json(const std::string& spec) {
    const BuilderSpec parsed = parse_builder_spec(spec);
    nlohmann::json params = nlohmann::json::object();
    if (!is_bvh_builder(parsed.name)) return params;
    for (const BuilderParam& p : find_builder(parsed.name).params) {
        const std::string* value = parsed.params.find(p.key);
        params[p.key] = value ? *value : p.default_value;
    }
    return params;
}

std::vector<Entry> make_entries(const Scene& scene, const FlatScene& flat, const BenchOptions& o, int threads) {
    std::vector<Entry> entries;
    FrameSettings frame;  // the frame auto rows plan for, as render_frames sets it
    frame.width = o.width, frame.height = o.height, frame.max_bounces = o.bounces, frame.material_albedo = o.material_albedo;
    o.workload.apply(frame);
    for (const std::string& toplevel : o.toplevels)
        for (const std::string& builder : toplevel == "flat" || o.blas_builders.empty() ? o.builders : o.blas_builders)
            for (const std::string& kernel : o.kernels)
                for (const std::string& traversal : o.traversals)
                    for (const std::string& intersector : o.intersectors)
                        for (const std::string& collapse : o.collapses)
                        for (const std::string& layout : o.layouts) {
                            // A binary layout is the same with every collapse: one row, not a copy of it. Compressed
                            // nodes are bvh8's: other kernels take the standard row only.
                            if (collapse != o.collapses.front() && kernel_width(kernel) == 2) continue;
                            if (layout == "compressed" && kernel_width(kernel) != 8 && o.layouts.size() > 1) continue;
                            // The direct emission is lbvh's alone, of flat trees: other rows take the other collapses.
                            if (collapse == "direct" && (builder != "lbvh" || toplevel != "flat") && o.collapses.size() > 1) continue;
                            // Another structure family (the kd-tree) has one kernel: one row, not one per BVH kernel,
                            // traversal mode or collapse.
                            const bool bvh = builder == "auto" || is_bvh_builder(spec_name(builder));
                            if (!bvh && (kernel != o.kernels.front() || traversal != o.traversals.front() ||
                                         collapse != o.collapses.front() || layout != o.layouts.front()))
                                continue;
                            CanopyOptions options{builder, optimiser_start(builder, o.start), kernel,
                                                  traversal == "robust", intersector == "watertight", toplevel};
                            if (!collapse.empty()) options.collapse = parse_collapse_method(collapse);
                            options.layout = parse_node_layout(layout);
                            if (builder != "auto") {
                                for (const float threshold : rebraid_thresholds_of(toplevel, o)) {
                                    options.rebraid_threshold = threshold;
                                    entries.push_back({make_canopy_accelerator(scene, flat, options)});
                                    if (toplevel == "rebraid") entries.back().rebraid_threshold = threshold;
                                    entries.back().builder_params = builder_params_json(builder);
                                }
                                continue;
                            }
                            if (toplevel != o.toplevels.front()) continue;  // auto chooses the top level itself
                            for (int frames : o.frames_planned) {
                                CanopyOptions planned = options;
                                planned.toplevel = "flat", planned.frames_planned = frames;
                                planned.auto_sample = frame_sample(scene, flat, frame);
                                entries.push_back({make_canopy_accelerator(scene, flat, planned)});
                            }
                        }
    const bool two_level = std::any_of(o.toplevels.begin(), o.toplevels.end(), [](const std::string& t) { return t != "flat"; });
    for (const std::string& quality : o.embree_qualities) {
        entries.push_back({make_embree_accelerator(flat, quality, threads)});
        if (two_level) entries.push_back({make_embree_two_level_accelerator(scene, flat, quality, threads)});
    }
    std::vector<Entry> rows = rows_per_tracer(std::move(entries), o);
    for (Entry& row : rows) {
        row.threads = threads;
        if (o.threads.size() > 1) row.thread_tag = " " + threads_text(threads);
    }
    return rows;
}

// The Embree row that ratios refer to: MEDIUM when present (like for like with binned SAH), with `tracer`; of
// several Embree stream rows (batch interfaces), the fastest.
const Entry* reference_of(const std::vector<Entry>& entries, TracerKind tracer = TracerKind::Single) {
    const Entry* ref = nullptr;
    for (const Entry& e : entries) {
        if (e.accel->library() != "embree" || e.tracer != tracer) continue;
        const bool medium = e.accel->quality() == "medium", ref_medium = ref && ref->accel->quality() == "medium";
        if (!ref || (medium && !ref_medium) || (medium == ref_medium && e.frame_mean() < ref->frame_mean())) ref = &e;
    }
    return ref;
}

template <class T>
nlohmann::json or_null(const std::optional<T>& v) {
    return v ? nlohmann::json(*v) : nlohmann::json(nullptr);
}

// An estimate of Embree's cache lines per ray from its layout's published sizes (BVH8 nodes of 256 bytes, leaves of
// Triangle4 blocks of 224 bytes, 4 triangles each) and the visits of the first canopy row of the same width, whose
// binned SAH tree stands in for Embree MEDIUM's: nodes x 4 lines + leaves x Triangle4 blocks per leaf x 3.5 lines.
std::optional<double> embree_lines_estimate(const std::vector<Entry>& entries) {
    for (const Entry& e : entries) {
        if (e.accel->library() != "canopy" || !e.visits || e.accel->kernel().rfind("bvh8", 0) != 0) continue;
        const TraversalCounts& v = *e.visits;
        if (v.leaf_nodes == 0) return std::nullopt;
        const double blocks_per_leaf = std::ceil(double(v.triangle_tests) / double(v.leaf_nodes) / 4.0);
        return (double(v.inner_nodes) * 4.0 + double(v.leaf_nodes) * blocks_per_leaf * 3.5) / double(e.counted_rays);
    }
    return std::nullopt;
}

std::string fixed1(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.1f", v);
    return text;
}

void print_table(const std::vector<Entry>& entries, uint64_t tris, SceneReport& out) {
    const Entry* ref = reference_of(entries);
    const std::optional<double> embree_lines = embree_lines_estimate(entries);
    int width = 22;  // the label column fits the longest label
    for (const Entry& e : entries) width = std::max(width, int(e.label().size()));
    out.printf("\n%-*s %10s %8s %10s %8s %11s %8s %7s %7s %9s %9s %7s %8s %8s %7s %8s %10s", width,
               "accelerator", "build ms", "Mprim/s", "frame ms", "Mrays/s", "rays/frame", "SAH", "EPO", "wSAH", "nodes",
               "leaves", "split%", "split ms", "%build", "alloc%", "MB", "img mean");
    out.printf(" %9s", "lines/ray");
    const bool streams = std::any_of(entries.begin(), entries.end(), [](const Entry& e) { return e.tracer == TracerKind::Stream; });
    if (ref) out.printf(" %9s %9s", "build/emb", "frame/emb");
    if (ref && streams) out.printf(" %10s", "frame/same");  // against Embree with the row's own tracer
    out.printf("\n");
    for (const Entry& e : entries) {
        const AcceleratorReport& r = e.report;
        const double frame = e.frame_mean();
        out.printf("%-*s %10.2f %8.2f %10.2f %8.2f %11.0f ", width, e.label().c_str(), e.build_min(),
                   double(tris) / e.build_min() / 1e3, frame, e.rays_per_frame() / frame / 1e3, e.rays_per_frame());
        if (r.sah) out.printf("%8.2f ", *r.sah);
        else out.printf("%8s ", "-");
        if (r.epo) out.printf("%7.2f ", *r.epo);
        else out.printf("%7s ", "-");
        if (r.layout_sah) out.printf("%7.2f ", *r.layout_sah);  // eq. 1 of the traversal layout, wide nodes
        else out.printf("%7s ", "-");
        if (r.nodes) out.printf("%9llu %9llu ", (unsigned long long)*r.nodes, (unsigned long long)*r.leaves);
        else out.printf("%9s %9s ", "-", "-");
        if (r.refs_per_tri) out.printf("%7.1f ", 100.0 * (*r.refs_per_tri - 1.0));  // two-level rows have none
        else out.printf("%7s ", "-");
        // Split pass time against this build's minimum (Table 4), reference slots allocated beyond one per triangle.
        if (r.split_ms) out.printf("%8.2f %8.1f %7.1f ", *r.split_ms, 100.0 * *r.split_ms / e.build_min(),
                                   100.0 * (*r.ref_capacity_per_tri - 1.0));
        else out.printf("%8s %8s %7s ", "-", "-", "-");
        out.printf("%8.1f %10.5f", r.bytes ? double(*r.bytes) / 1e6 : 0.0, e.image_mean);
        if (const std::optional<double> lines = e.per_ray(&TraversalCounts::cache_lines)) out.printf(" %9.1f", *lines);
        else if (e.accel->library() == "embree" && embree_lines) out.printf(" %9s", ("~" + fixed1(*embree_lines)).c_str());
        else out.printf(" %9s", "-");
        if (ref) out.printf(" %9.3f %9.3f", e.build_min() / ref->build_min(), frame / ref->frame_mean());
        if (const Entry* same = reference_of(entries, e.tracer); ref && streams && same)
            out.printf(" %10.3f", frame / same->frame_mean());
        out.printf("\n");
    }
    if (ref) out.printf("ratios against %s, measured in this run%s\n", ref->label().c_str(),
                        streams ? "; frame/same: against Embree MEDIUM with the row's tracer" : "");
    out.printf("lines/ray: 64-byte lines of the nodes and leaves a ray of the first timed frame visits (single-ray "
               "counting kernel)%s\n", embree_lines ? "; ~Embree: estimated from its node and leaf sizes over the "
               "first canopy bvh8 row's visits" : "");
    for (const Entry& e : entries)
        if (e.tracer == TracerKind::Stream)
            out.printf("%s: sorting %.1f%% of the frame, stream memory %.1f MB (all threads), batches path by path "
                       "%llu of %llu\n", e.label().c_str(), 100.0 * e.sort_share(), double(e.stream->bytes.load()) / 1e6,
                       (unsigned long long)e.stream->path_batches.load(), (unsigned long long)e.stream->batches.load());
}

// An auto row's calibration, from its last build: every candidate, measured or predicted.
nlohmann::json auto_json(const AutoChoice* choice, int frames) {
    if (!choice) return nullptr;
    nlohmann::json candidates = nlohmann::json::array();
    for (const CandidateEstimate& c : choice->candidates)
        candidates.push_back({{"builder", c.builder}, {"toplevel", c.toplevel}, {"measured", c.measured},
                              {"build_ms", c.build_ms}, {"frame_ms", c.frame_ms},
                              {"sample_ms", c.measured ? nlohmann::json(c.sample_ms) : nlohmann::json(nullptr)},
                              {"sampled_frame_ms", c.measured ? nlohmann::json(c.sampled_frame_ms) : nlohmann::json(nullptr)},
                              {"sample_weight", c.measured ? nlohmann::json(c.sample_weight) : nlohmann::json(nullptr)},
                              {"time_to_image_ms", c.time_to_image_ms(frames)}, {"note", c.note}});
    return {{"calibration_ms", choice->calibration_ms}, {"budget_ms", choice->budget_ms}, {"candidates", candidates}};
}

// The rows of one thread count.
nlohmann::json results_json(const std::vector<Entry>& entries, uint64_t tris) {
    nlohmann::json results = nlohmann::json::array();
    const std::optional<double> embree_lines = embree_lines_estimate(entries);
    for (const Entry& e : entries) {
        const AcceleratorReport& r = e.report;
        const bool canopy = e.accel->library() == "canopy";
        const double frame = e.frame_mean();
        results.push_back({{"accel", e.accel->library()},
                           {"host", distributed::host()},
                           {"builder", canopy ? nlohmann::json(e.accel->builder()) : nlohmann::json(nullptr)},
                           {"kernel", canopy ? nlohmann::json(e.accel->kernel()) : nlohmann::json(nullptr)},
                           {"chosen", e.accel->chosen().empty() ? nlohmann::json(nullptr) : nlohmann::json(e.accel->chosen())},
                           {"reason", e.accel->reason().empty() ? nlohmann::json(nullptr) : nlohmann::json(e.accel->reason())},
                           {"auto", auto_json(e.accel->auto_choice(), e.accel->frames_planned())},
                           {"frames_planned", e.accel->frames_planned() ? nlohmann::json(e.accel->frames_planned()) : nlohmann::json(nullptr)},
                           {"quality", canopy ? nlohmann::json(nullptr) : nlohmann::json(e.accel->quality())},
                           {"tracer", tracer_name(e.tracer)},
                           {"workload", workload_name(e.settings.workload)},
                           {"threads", e.threads},
                           {"rebraid_threshold", or_null(e.rebraid_threshold)},
                           {"builder_params", e.builder_params},
                           {"batch_traversal", e.tracer != TracerKind::Stream ? nlohmann::json(nullptr)
                                               : canopy ? nlohmann::json(batch_traversal_name(e.settings.batch_traversal))
                                               : nlohmann::json(e.settings.embree_packets ? "rtcIntersect16" : "rtcIntersect1M")},
                           {"sort_share", e.tracer == TracerKind::Stream ? nlohmann::json(e.sort_share()) : nlohmann::json(nullptr)},
                           {"stream_bytes", e.tracer == TracerKind::Stream ? nlohmann::json(e.stream->bytes.load()) : nlohmann::json(nullptr)},
                           {"stream_batches", e.tracer != TracerKind::Stream ? nlohmann::json(nullptr)
                                              : nlohmann::json{{"way", stream_batching_name(e.settings.stream_batching)},
                                                               {"batches", e.stream->batches.load()},
                                                               {"path_by_path", e.stream->path_batches.load()}}},
                           {"build_ms_min", e.build_min()},
                           {"build_ms_median", median(e.build_ms)},
                           {"mprims_per_s", double(tris) / e.build_min() / 1e3},
                           {"frame_ms_mean", frame},
                           {"frame_ms_median", median(e.frame_ms)},
                           {"rays_per_frame", e.rays_per_frame()},
                           {"mrays_per_s", e.rays_per_frame() / frame / 1e3},
                           {"sah", or_null(r.sah)},
                           {"epo", or_null(r.epo)},
                           {"layout_sah", or_null(r.layout_sah)},
                           {"nodes", or_null(r.nodes)},
                           {"leaves", or_null(r.leaves)},
                           {"refs_per_tri", or_null(r.refs_per_tri)},
                           {"split_ms", or_null(r.split_ms)},
                           {"ref_capacity_per_tri", or_null(r.ref_capacity_per_tri)},
                           {"objects_ms", or_null(r.objects_ms)},
                           {"top_level_ms", or_null(r.top_level_ms)},
                           {"brefs", or_null(r.brefs)},
                           {"bytes", or_null(r.bytes)},
                           {"inner_per_ray", or_null(e.per_ray(&TraversalCounts::inner_nodes))},
                           {"leaves_per_ray", or_null(e.per_ray(&TraversalCounts::leaf_nodes))},
                           {"triangles_per_ray", or_null(e.per_ray(&TraversalCounts::triangle_tests))},
                           {"lines_per_ray", or_null(e.per_ray(&TraversalCounts::cache_lines))},
                           {"lines_per_ray_estimate", canopy ? nlohmann::json(nullptr) : or_null(embree_lines)},
                           {"image_mean", e.image_mean},
                           {"time_to_image_ms", {{"1", e.build_min() + frame},
                                                 {"16", e.build_min() + 16 * frame},
                                                 {"256", e.build_min() + 256 * frame}}}});
    }
    return results;
}

nlohmann::json to_json(const nlohmann::json& results, const BenchOptions& o, uint64_t tris) {
    return {{"scene", o.scene}, {"tris", tris}, {"threads", o.threads}, {"width", o.width},
            {"height", o.height}, {"bounces", o.bounces}, {"stream_paths", o.stream_paths},
            {"workload", o.workload.workload}, {"results", results}};
}

// The progress line's text for a row's step: "bench SCENE, ROW: build 2 of 20".
void show_progress(const std::string& scene, const Entry& e, const std::string& step, bool phase = false) {
    if (!progress::shown()) return;
    const std::string text = "bench " + scene + ", " + e.label() + ": " + step;
    phase ? progress::phase(text) : progress::update(text);
}

std::string step_of(const char* step, int i, int n) { return std::string(step) + " " + std::to_string(i) + " of " + std::to_string(n); }

// Builds every entry `builds` times, alternating between them; the minimum is reported.
void build_all(std::vector<Entry>& entries, int builds, const std::string& scene) {
    for (int round = 0; round < builds; ++round) {
        for (size_t i = 0; i < entries.size(); ++i) {
            if (!builds_its_accelerator(entries, i)) continue;
            show_progress(scene, entries[i], step_of("build", round + 1, builds), round == 0 && i == 0);
            entries[i].accel->prepare();
            const auto start = Clock::now();
            entries[i].accel->build();
            entries[i].build_ms.push_back(ms_since(start));
        }
    }
    for (size_t i = 0; i < entries.size(); ++i)
        if (!builds_its_accelerator(entries, i)) entries[i].build_ms = entries[i - 1].build_ms;
}

// Dynamic-in-static (Benthin et al. 2017, sec. 6.3): the object takes its place for `frame` in the flat scene,
// which every entry traces and shades, then each entry rebuilds what the move invalidates, timed.
void move_all(std::vector<Entry>& entries, const DynamicObject& object, uint32_t frame, FlatScene& flat) {
    const PlacementMove move = move_dynamic_object(object, frame, flat);
    for (Entry& e : entries) {
        const auto start = Clock::now();
        e.accel->move(move);
        e.rebuild_ms.push_back(ms_since(start));
    }
}

// The first timed frame again, untimed, one ray at a time through the counting kernel, once per canopy accelerator
// (its stream rows trace the same rays through the same tree).
void count_visits(std::vector<Entry>& entries, const std::vector<ShadingScene>& shading, const PinholeCamera& camera,
                  const BenchOptions& o) {
    for (size_t i = 0; i < entries.size(); ++i) {
        Entry& e = entries[i];
        if (e.accel->library() != "canopy") continue;
        if (!builds_its_accelerator(entries, i)) {
            e.visits = entries[i - 1].visits, e.counted_rays = entries[i - 1].counted_rays;
            continue;
        }
        show_progress(o.scene, e, "counting visits", i == 0);
        std::tie(e.visits, e.counted_rays) = count_frame(*e.accel, shading[i], camera, 1);
    }
}

// One untimed warm-up frame, then the timed frames, alternating between entries; with a dynamic object, it moves
// before each timed frame (the warm-up shows it at rest, as built).
void render_frames(std::vector<Entry>& entries, const Scene& scene, FlatScene& flat, const BenchOptions& o,
                   const DynamicObject* dynamic) {
    std::vector<ShadingScene> shading;
    for (Entry& e : entries) {
        FrameSettings& s = e.settings;
        s.width = o.width, s.height = o.height, s.max_bounces = o.bounces, s.material_albedo = o.material_albedo;
        s.tracer = e.tracer, s.stream_paths = o.stream_paths;
        o.workload.apply(s);
        shading.push_back({flat, s, e.tracer == TracerKind::Stream ? e.stream.get() : nullptr});
    }
    const PinholeCamera camera(scene_camera(scene, flat), o.width, o.height);
    std::vector<Image> images(entries.size(), Image(o.width, o.height));
    for (size_t i = 0; i < entries.size(); ++i) {  // warm-up
        show_progress(o.scene, entries[i], "warm-up frame", i == 0);
        render(*entries[i].accel, shading[i], camera, 0, images[i]);
    }
    for (Image& image : images) image.clear();
    for (Entry& e : entries) e.stream->sort_ns = 0, e.stream->batches = 0, e.stream->path_batches = 0;
    for (int frame = 1; frame <= o.frames; ++frame) {
        if (dynamic) move_all(entries, *dynamic, uint32_t(frame), flat);
        for (size_t i = 0; i < entries.size(); ++i) {
            show_progress(o.scene, entries[i], step_of("frame", frame, o.frames), frame == 1 && i == 0);
            const auto start = Clock::now();
            entries[i].rays += render(*entries[i].accel, shading[i], camera, uint32_t(frame), images[i]);
            entries[i].frame_ms.push_back(ms_since(start));
        }
    }
    for (size_t i = 0; i < entries.size(); ++i) entries[i].image_mean = images[i].mean(o.frames);
    if (!dynamic) count_visits(entries, shading, camera, o);
}

// --rays: one untimed pass over the recorded rays, then o.frames timed passes, alternating between entries; each
// entry's answers counted against the recorded hits.
void replay_frames(std::vector<Entry>& entries, const std::vector<RecordedRay>& rays, const BenchOptions& o) {
    std::vector<std::vector<Hit>> hits(entries.size(), std::vector<Hit>(rays.size()));
    for (Entry& e : entries) e.settings.tracer = e.tracer;
    for (size_t i = 0; i < entries.size(); ++i) {
        show_progress(o.scene, entries[i], "warm-up pass", i == 0);
        replay(*entries[i].accel, entries[i].settings, rays, hits[i]);
    }
    for (int frame = 1; frame <= o.frames; ++frame)
        for (size_t i = 0; i < entries.size(); ++i) {
            show_progress(o.scene, entries[i], step_of("pass", frame, o.frames), frame == 1 && i == 0);
            const auto start = Clock::now();
            replay(*entries[i].accel, entries[i].settings, rays, hits[i]);
            entries[i].frame_ms.push_back(ms_since(start));
            entries[i].rays += rays.size();
        }
    for (size_t i = 0; i < entries.size(); ++i)
        for (size_t k = 0; k < rays.size(); ++k) {
            const Hit &got = hits[i][k], &recorded = rays[k].hit;
            const bool same_t = std::bit_cast<uint32_t>(got.t) == std::bit_cast<uint32_t>(recorded.t);
            if (got.found() != recorded.found()) ++entries[i].answers_differ;
            else if (rays[k].any || !got.found()) continue;
            else if (got.prim != recorded.prim) ++(same_t ? entries[i].ties : entries[i].answers_differ);
            else if (!same_t) ++entries[i].t_bits_differ;
        }
}

void write_json(const nlohmann::json& j, const std::string& path) {
    if (path.empty()) return;
    std::ofstream out(path);
    out << j.dump(2) << "\n";
    if (!out) throw std::runtime_error(path + ": cannot write benchmark JSON");
    std::printf("wrote %s\n", path.c_str());
}

// Table 3's baseline, "two-level + dyn": the first canopy two-level row.
const Entry* two_level_row(const std::vector<Entry>& entries) {
    for (const Entry& e : entries)
        if (e.accel->library() == "canopy" && e.accel->builder().starts_with("two-level/")) return &e;
    return nullptr;
}

// Sec. 6.3, Table 3: per frame, the rebuild, the frame and their sum, the sums against plain two-level.
void print_dynamic_table(const std::vector<Entry>& entries, SceneReport& out) {
    const Entry* ref = two_level_row(entries);
    out.printf("\n%-30s %11s %11s %11s %11s %11s %8s %7s %10s\n", "accelerator", "first build", "rebuild ms",
               "render ms", "total ms", "total/2lvl", "wSAH", "BRefs", "img mean");
    for (const Entry& e : entries) {
        const AcceleratorReport& r = e.report;
        out.printf("%-30s %11.2f %11.2f %11.2f %11.2f ", e.label().c_str(), e.build_min(), e.rebuild_mean(),
                   e.frame_mean(), e.total_mean());
        if (ref) out.printf("%10.2fx ", e.total_mean() / ref->total_mean());
        else out.printf("%11s ", "-");
        if (r.layout_sah) out.printf("%8.2f ", *r.layout_sah);
        else out.printf("%8s ", "-");
        if (r.brefs) out.printf("%7llu ", (unsigned long long)*r.brefs);
        else out.printf("%7s ", "-");
        out.printf("%10.5f\n", e.image_mean);
    }
    out.printf("per frame means over the timed frames; wSAH and BRefs of the last frame's structure\n");
}

nlohmann::json dynamic_json(const std::vector<Entry>& entries, const BenchOptions& o, const DynamicObject& object,
                            uint64_t tris) {
    nlohmann::json results = nlohmann::json::array();
    for (const Entry& e : entries) {
        const bool canopy = e.accel->library() == "canopy";
        results.push_back({{"accel", e.accel->library()},
                           {"host", distributed::host()},
                           {"label", e.label()},
                           {"builder", canopy ? nlohmann::json(e.accel->builder()) : nlohmann::json(nullptr)},
                           {"kernel", canopy ? nlohmann::json(e.accel->kernel()) : nlohmann::json(nullptr)},
                           {"quality", canopy ? nlohmann::json(nullptr) : nlohmann::json(e.accel->quality())},
                           {"rebraid_threshold", or_null(e.rebraid_threshold)},
                           {"first_build_ms", e.build_min()},
                           {"rebuild_ms_mean", e.rebuild_mean()},
                           {"rebuild_ms_median", median(e.rebuild_ms)},
                           {"render_ms_mean", e.frame_mean()},
                           {"render_ms_median", median(e.frame_ms)},
                           {"total_ms_mean", e.total_mean()},
                           {"rays_per_frame", e.rays_per_frame()},
                           {"layout_sah", or_null(e.report.layout_sah)},
                           {"top_level_ms_last", or_null(e.report.top_level_ms)},
                           {"brefs", or_null(e.report.brefs)},
                           {"image_mean", e.image_mean}});
    }
    const nlohmann::json moving{{"placement", object.placement},     {"name", object.name},
                                {"triangles", object.triangles.size()}, {"path_radius", object.path_radius},
                                {"frames_per_turn", kFramesPerTurn}};
    return {{"scene", o.scene}, {"tris", tris},     {"threads", o.threads}, {"width", o.width},
            {"height", o.height}, {"bounces", o.bounces}, {"frames", o.frames},  {"dynamic", moving},
            {"results", results}};
}

void report_static(const std::vector<Entry>& entries, uint64_t tris, bool explain, SceneReport& out) {
    print_table(entries, tris, out);
    for (const Entry& e : entries) {
        if (!e.accel->reason().empty()) out.printf("%s: %s\n", e.label().c_str(), e.accel->reason().c_str());
        if (const AutoChoice* choice = e.accel->auto_choice(); choice && explain)
            out.printf("%s", canopy::explain(*choice, e.accel->frames_planned()).c_str());
        if (e.report.top_level_ms)
            out.printf("%s: object trees %.2f ms, top level %.3f ms (fastest of the builds) over %llu BRefs\n", e.label().c_str(),
                       *e.report.objects_ms, *e.report.top_level_ms, (unsigned long long)*e.report.brefs);
    }
}

// "ao (4 rays of length 1.5)" or the workload's name.
std::string workload_text(const WorkloadOptions& w) {
    if (w.workload != "ao") return w.workload;
    const std::string length = w.ao_length > 0.0f ? "length " + std::to_string(w.ao_length) : "a tenth of the diagonal";
    return "ao (" + std::to_string(w.ao_rays) + " rays of " + length + ")";
}

// "2" or "1, 2": the thread counts of the protocol line ("all" for 0).
std::string thread_counts_text(const std::vector<int>& counts) {
    std::string text;
    for (int t : counts) text += (text.empty() ? "" : ", ") + (t ? std::to_string(t) : std::string("all"));
    return text;
}

// A scene of a bench, loaded and flattened (timed: reported, not in build times).
struct LoadedScene {
    Scene scene;
    FlatScene flat;  // a dynamic object moves in it
    double load_ms = 0, flatten_ms = 0;
    MemoryEstimate memory;  // the estimate the scene was admitted with
    std::optional<std::vector<RecordedRay>> rays;  // --rays
};

std::shared_ptr<LoadedScene> load_bench_scene(const BenchOptions& o) {
    auto loaded = std::make_shared<LoadedScene>();
    auto start = Clock::now();
    const std::vector<BuildPlan> plans = build_plans(o);
    const bool stream = std::count(o.tracers.begin(), o.tracers.end(), "stream") > 0;
    const uint64_t frames = frame_bytes(o.width, o.height, plans.size() * o.tracers.size(), stream, o.stream_paths);
    loaded->scene = load_scene_within_memory(o.scene, plans, frames, o.memory_limit, &loaded->memory);
    loaded->load_ms = ms_since(start);
    start = Clock::now();
    loaded->flat = flatten(loaded->scene);
    loaded->flatten_ms = ms_since(start);
    if (!o.rays_path.empty()) loaded->rays = read_rays(o.rays_path);
    return loaded;
}

// Sec. 6.3's protocol: one thread count, every row moving its accelerator's dynamic object.
nlohmann::json bench_dynamic(const BenchOptions& o, LoadedScene& loaded, const DynamicObject& dynamic, SceneReport& out) {
    if (o.tracers.size() > 1) throw std::invalid_argument("--dynamic takes one --tracer (its rows move their accelerator)");
    if (o.threads.size() > 1) throw std::invalid_argument("--dynamic takes one --threads (its rows move the scene)");
    std::optional<tbb::global_control> limit;
    if (o.threads[0] > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(o.threads[0]));
    std::vector<Entry> entries = make_entries(loaded.scene, loaded.flat, o, o.threads[0]);
    build_all(entries, 1, o.scene);
    render_frames(entries, loaded.scene, loaded.flat, o, &dynamic);
    progress::finish();
    for (Entry& e : entries) e.report = e.accel->report(false);
    print_dynamic_table(entries, out);
    return dynamic_json(entries, o, dynamic, loaded.flat.triangles.size());
}

// Each thread count is a whole protocol run of its own, with Embree on as many threads; its rows' ratios are
// against the Embree row of the same count.
nlohmann::json bench_static(const BenchOptions& o, LoadedScene& loaded, SceneReport& out) {
    const uint64_t tris = loaded.flat.triangles.size();
    nlohmann::json results = nlohmann::json::array();
    for (const int threads : o.threads) {
        std::optional<tbb::global_control> limit;
        if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(threads));
        if (o.threads.size() > 1) out.printf("\n%s:", threads_text(threads).c_str());
        std::vector<Entry> entries = make_entries(loaded.scene, loaded.flat, o, threads);
        build_all(entries, o.builds, o.scene);
        if (loaded.rays) replay_frames(entries, *loaded.rays, o);
        else render_frames(entries, loaded.scene, loaded.flat, o, nullptr);
        progress::finish();  // before the table, on stdout
        for (Entry& e : entries) e.report = e.accel->report(o.epo);
        report_static(entries, tris, o.explain, out);
        nlohmann::json rows = results_json(entries, tris);
        for (size_t i = 0; loaded.rays && i < entries.size(); ++i) {
            const Entry& e = entries[i];
            out.printf("%s: of %zu recorded answers, %llu differ (hit or not, or another triangle at another distance), %llu "
                       "ties (another triangle at the same distance), %llu on the same triangle at another distance\n",
                       e.label().c_str(), loaded.rays->size(), (unsigned long long)e.answers_differ, (unsigned long long)e.ties,
                       (unsigned long long)e.t_bits_differ);
            rows[i]["workload"] = "recorded";
            rows[i]["replay"] = {{"file", o.rays_path}, {"rays", loaded.rays->size()}, {"answers_differ", e.answers_differ},
                                 {"ties", e.ties}, {"t_bits_differ", e.t_bits_differ}};
        }
        for (nlohmann::json& row : rows) results.push_back(std::move(row));
    }
    return to_json(results, o, tris);
}

// One scene's bench (o.scene): every accelerator built and rendered alternately in this process; its JSON.
nlohmann::json bench_scene(const BenchOptions& o, LoadedScene& loaded, SceneReport& out) {
    const uint64_t tris = loaded.flat.triangles.size();
    auto start = Clock::now();
    (void)make_prim_refs(loaded.flat.triangles);
    const double primref_ms = ms_since(start);
    out.printf("scene %s: %llu triangles; load %.1f ms, flatten %.1f ms, PrimRefs %.1f ms (not in build times)%s\n",
               o.scene.c_str(), (unsigned long long)tris, loaded.load_ms, loaded.flatten_ms, primref_ms,
               distributed::where().c_str());
    out.printf("memory estimate: %s\n", loaded.memory.describe().c_str());
    const std::optional<DynamicObject> dynamic =
        o.dynamic ? std::optional(choose_dynamic_object(loaded.scene, loaded.flat, *o.dynamic)) : std::nullopt;
    if (dynamic) {
        out.printf("dynamic-in-static (Benthin et al. 2017, sec. 6.3, Table 3): placement %u '%s', %zu triangles "
                   "(%.2f%% of the scene), turning about an axis %.4g from its centre, a turn in %u frames\n",
                   dynamic->placement, dynamic->name.c_str(), dynamic->triangles.size(),
                   100.0 * double(dynamic->triangles.size()) / double(tris), dynamic->path_radius, kFramesPerTurn);
        out.printf("protocol: %dx%d, %d bounces, 1 first build, then per frame a move, a timed rebuild and a timed "
                   "frame; %d frames (mean) after 1 warm-up at rest, threads %s\n",
                   o.width, o.height, o.bounces, o.frames, thread_counts_text(o.threads).c_str());
        return bench_dynamic(o, loaded, *dynamic, out);
    }
    if (loaded.rays) {
        out.printf("replay: %zu rays of %s, %d builds (min), %d passes over them (mean) after 1 warm-up, threads %s\n",
                   loaded.rays->size(), o.rays_path.c_str(), o.builds, o.frames, thread_counts_text(o.threads).c_str());
        return bench_static(o, loaded, out);
    }
    out.printf("protocol: %dx%d, workload %s, %d bounces, %d builds (min), %d frames (mean) after 1 warm-up, threads %s%s\n",
               o.width, o.height, workload_text(o.workload).c_str(), o.bounces, o.builds, o.frames, thread_counts_text(o.threads).c_str(),
               std::count(o.tracers.begin(), o.tracers.end(), "stream")
                   ? ("; stream batches of " + std::to_string(o.stream_paths) + " paths").c_str() : "");
    return bench_static(o, loaded, out);
}

// What `canopy bench` parses besides BenchOptions itself: the values that become its fields once parsed.
struct BenchCommand {
    BenchOptions options;
    std::vector<std::string> scenes, accels, qualities{"medium"};
    std::string dynamic;
    std::vector<int> size{1024, 768};
    bool quiet = false;
    std::vector<std::string> esc_area_limits, alpha_values;  // the --esc-sa-max and --sbvh-alpha aliases' values
    CLI::Option *dynamic_option = nullptr, *rebraid_option = nullptr, *esc_option = nullptr, *alpha_option = nullptr;
};

// Options that take each value once, for a row each or the whole run.
void add_row_options(CLI::App& bench, BenchCommand& c) {
    BenchOptions& b = c.options;
    bench.add_option("--builder", b.builders, "Builders: " + builder_names())->delimiter(',')->capture_default_str();
    bench.add_option("--start", b.start, "Optimisers among the builders: builder of their start tree");
    bench.add_option("--toplevel", b.toplevels, "Top levels: flat, two-level (object BVHs under a BVH over instances), rebraid (Benthin 2017)")
        ->delimiter(',')->check(CLI::IsMember({"flat", "two-level", "rebraid"}))->capture_default_str();
    c.rebraid_option = bench.add_option("--rebraid-threshold", b.rebraid_thresholds,
                      "Rebraid rows: open BRefs wider than this share of their segment's extent, 0 to 1 (sec. 4.2); a row each")
        ->delimiter(',')->check(CLI::Range(0.0, 1.0))->capture_default_str();
    c.esc_option = bench.add_option("--esc-sa-max", c.esc_area_limits,
                      "esc rows, a row each: --builder esc:sa_max=VALUE for each value")->delimiter(',');
    c.alpha_option = bench.add_option("--sbvh-alpha", c.alpha_values,
                      "sbvh rows, a row each: --builder sbvh:alpha=VALUE for each value")->delimiter(',');
    bench.add_option("--blas-builder", b.blas_builders,
                      "Two-level top levels: builders of the object BVHs, a row each (default: the --builder list)")
        ->delimiter(',');
    bench.add_option("--frames-planned", b.frames_planned, "Frames that --builder auto plans time to image for (a row each)")
        ->delimiter(',')->check(CLI::Range(1, 1 << 24))->capture_default_str();
    bench.add_flag("--explain", b.explain, "--builder auto: every candidate's predicted or measured build and frame time, and the choice");
    bench.add_option("--kernel", b.kernels, "Kernels: auto (widest), bvh2, bvh4, bvh8")->delimiter(',')->capture_default_str();
    bench.add_option("--accel", c.accels, "Reference accelerators in the same run: embree")->delimiter(',')
        ->check(CLI::IsMember({"embree"}));
    bench.add_option("--embree-quality", c.qualities, "Embree qualities: low, medium, high")->delimiter(',')
        ->check(CLI::IsMember({"low", "medium", "high"}))->capture_default_str();
    bench.add_option("--traversal", b.traversals, "Traversal modes: robust, fast")->delimiter(',')
        ->check(CLI::IsMember({"robust", "fast"}))->capture_default_str();
    bench.add_option("--intersector", b.intersectors, "Intersectors: watertight, moller (Möller–Trumbore)")->delimiter(',')
        ->check(CLI::IsMember({"watertight", "moller"}))->capture_default_str();
    bench.add_option("--collapse", b.collapses, std::string(kCollapseHelp) + "; a row each")
        ->delimiter(',')->check(CLI::IsMember({"optimal", "greedy", "direct"}));
    bench.add_option("--layout", b.layouts, std::string(kLayoutHelp) + "; a row each")
        ->delimiter(',')->check(CLI::IsMember({"standard", "compressed"}))->capture_default_str();
    bench.add_option("--tracer", b.tracers, "Tracers: single (one path at a time), stream (each bounce's rays as one sorted batch)")
        ->delimiter(',')->check(CLI::IsMember({"single", "stream"}))->capture_default_str();
    bench.add_option("--batch-traversal", b.batch_traversals, std::string(kBatchTraversalHelp) + "; a stream row each")
        ->delimiter(',')->check(CLI::IsMember({"single", "packet", "stream"}))->capture_default_str();
    bench.add_option("--stream-batches", b.stream_batchings, std::string(kStreamBatchingHelp) + "; a stream row each")
        ->delimiter(',')->check(CLI::IsMember({"measured", "wavefront", "paths"}))->capture_default_str();
    bench.add_option("--embree-stream", b.embree_streams,
                      "Stream tracer: Embree's batch interface, a stream row each: 1m (rtcIntersect1M, incoherent), 16 (rtcIntersect16 packets)")
        ->delimiter(',')->check(CLI::IsMember({"1m", "16"}))->capture_default_str();
}

// The protocol's options: how much is measured, and how.
void add_protocol_options(CLI::App& bench, BenchCommand& c) {
    BenchOptions& b = c.options;
    bench.add_option("--builds", b.builds, "Builds (minimum reported)")->check(CLI::Range(1, 10000))->capture_default_str();
    bench.add_option("--frames", b.frames, "Timed frames after one warm-up")->check(CLI::Range(1, 10000))->capture_default_str();
    add_workload_options(bench, b.workload);
    bench.add_option("--rays", b.rays_path,
                     "Replay a ray file (canopy rays record) instead of rendering frames: each row traces exactly those rays, "
                     "its answers counted against the recorded hits")
        ->check(CLI::ExistingFile);
    bench.add_option("--bounces", b.bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    bench.add_option("--json", b.json_path, "Write results as JSON");
    bench.add_flag("!--no-epo", b.epo, "Skip EPO in the report (minutes on millions of triangles)");
    bench.add_option("--threads", b.threads, "Threads for every library (0: all); a list runs the whole bench once per count")
        ->delimiter(',')->check(CLI::Range(0, 4096))->capture_default_str();
    bench.add_flag("--materials", b.material_albedo, "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light");
    bench.add_option("--stream-paths", b.stream_paths, "Stream tracer: paths in flight per batch")
        ->check(CLI::Range(1, 1 << 24))->capture_default_str();
    c.dynamic_option =
        bench.add_option("--dynamic", c.dynamic,
                          "Dynamic-in-static (Benthin 2017, Table 3): this object moves every frame; each frame's rebuild "
                          "and render are timed. An object or mesh name, a placement index, or auto (alone: the largest "
                          "object spanning at most a quarter of the scene); --builds is then 1")
            ->expected(0, 1)->default_str("auto");
    add_memory_limit_option(bench, b.memory_limit);
    bench.add_flag("--quiet", c.quiet, kQuietHelp);
    bench.add_option("--size", c.size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
}

bool contains_name(const std::vector<std::string>& list, const char* name) { return std::find(list.begin(), list.end(), name) != list.end(); }

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

// --rays replays one scene's recorded rays in place of frames: options about frames contradict it.
void check_replay_options(const BenchCommand& c, const BenchOptions& b) {
    if (c.scenes.size() != 1)
        throw std::invalid_argument("--rays: the rays of one scene, not " + std::to_string(c.scenes.size()) + " scenes (their triangles are numbered per scene)");
    if (b.dynamic) throw std::invalid_argument("--rays: replays recorded rays, not --dynamic frames");
    if (b.workload.workload != WorkloadOptions{}.workload)
        throw std::invalid_argument("--workload " + b.workload.workload + ": --rays replays rays recorded with their own workload");
}

// The parsed values as BenchOptions, refused (on every rank) where options contradict each other.
BenchOptions parsed_options(const BenchCommand& c) {
    BenchOptions b = c.options;
    b.width = c.size[0], b.height = c.size[1];
    if (!c.accels.empty()) b.embree_qualities = c.qualities;
    if (c.dynamic_option->count()) b.dynamic = c.dynamic;
    distributed::checked([&] {
        if (c.rebraid_option->count() && !contains_name(b.toplevels, "rebraid"))
            throw std::invalid_argument("--rebraid-threshold: only with --toplevel rebraid");
        if (!b.rays_path.empty()) check_replay_options(c, b);
        if (!b.json_path.empty() && distributed::is_root()) check_output_path("--json", b.json_path);
        b.builders = join_builder_specs(b.builders), b.blas_builders = join_builder_specs(b.blas_builders);
        if (c.esc_option->count()) apply_param_alias("--esc-sa-max", "esc", kEscSaMaxKey, c.esc_area_limits, b);
        if (c.alpha_option->count()) apply_param_alias("--sbvh-alpha", "sbvh", "alpha", c.alpha_values, b);
        for (const std::string& blas : b.blas_builders) check_blas_builder(blas, b.toplevels);
        for (const std::string& builder : b.builders)
            if (builder != "auto") check_builder_name(builder);
    });
    return b;
}

}  // namespace

void register_bench(CLI::App& canopy) {
    auto c = std::make_shared<BenchCommand>();
    CLI::App* bench = canopy.add_subcommand("bench", "Benchmark builders and kernels against Embree (BENCHMARK.md)");
    bench->add_option("scenes", c->scenes, "Scenes, each benched in turn: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")
        ->required();
    add_row_options(*bench, *c);
    add_protocol_options(*bench, *c);
    bench->callback([c] {
        progress::start(c->quiet);
        run_bench(c->scenes, parsed_options(*c));
    });
}

// Row by row as make_entries makes them. Rows that differ only by traversal mode, intersector or collapse are
// separate builds of the same size; auto has a row per planned frame count (under the first top level only, as it
// chooses its own) and rebraid one per opening threshold.
std::vector<BuildPlan> build_plans(const BenchOptions& o) {
    std::vector<BuildPlan> plans;
    const size_t copies = o.traversals.size() * o.intersectors.size() * o.collapses.size() * o.layouts.size();
    for (const std::string& toplevel : o.toplevels)
        for (const std::string& builder : toplevel == "flat" || o.blas_builders.empty() ? o.builders : o.blas_builders)
            for (const std::string& kernel : o.kernels) {
                const bool auto_rows = builder == "auto";
                if (auto_rows && toplevel != o.toplevels.front()) continue;
                const size_t rows = copies * (auto_rows ? o.frames_planned.size()
                                                        : rebraid_thresholds_of(toplevel, o).size());
                plans.insert(plans.end(), rows, make_build_plan(builder, kernel_width(kernel), !auto_rows && toplevel != "flat"));
            }
    const bool two_level = std::any_of(o.toplevels.begin(), o.toplevels.end(), [](const std::string& t) { return t != "flat"; });
    for (size_t q = 0; q < o.embree_qualities.size(); ++q) {
        plans.push_back({"embree", 8, false});
        if (two_level) plans.push_back({"embree", 8, true});
    }
    return plans;
}

namespace {

// JSON writes a NaN or a missing figure as null: read back as NaN.
double number_or_nan(const nlohmann::json& row, const char* key) {
    return row.contains(key) && row[key].is_number() ? row[key].get<double>() : BenchRow::kNone;
}

// A row of results_json or dynamic_json, read back after run_per_scene gathered it.
BenchRow bench_row(const nlohmann::json& r) {
    const auto text = [&](const char* key) { return r.at(key).is_string() ? r.at(key).get<std::string>() : std::string(); };
    BenchRow row{text("accel"), text("builder"), text("quality")};
    row.threads = r.contains("threads") ? r.at("threads").get<int>() : 0;
    if (r.at("rebraid_threshold").is_number()) row.rebraid_threshold = r.at("rebraid_threshold").get<double>();
    if (r.contains("builder_params") && r.at("builder_params").is_object())
        for (const auto& param : r.at("builder_params").items()) row.builder_params.set(param.key(), param.value().get<std::string>());
    const bool dynamic = r.contains("rebuild_ms_mean");
    row.build_ms_min = number_or_nan(r, dynamic ? "first_build_ms" : "build_ms_min");
    row.frame_ms_mean = number_or_nan(r, dynamic ? "render_ms_mean" : "frame_ms_mean");
    row.sah = number_or_nan(r, "sah"), row.layout_sah = number_or_nan(r, "layout_sah");
    row.refs_per_tri = number_or_nan(r, "refs_per_tri"), row.split_ms = number_or_nan(r, "split_ms");
    row.bytes = number_or_nan(r, "bytes"), row.brefs = number_or_nan(r, "brefs");
    row.top_level_ms = number_or_nan(r, dynamic ? "top_level_ms_last" : "top_level_ms");
    row.inner_per_ray = number_or_nan(r, "inner_per_ray"), row.triangles_per_ray = number_or_nan(r, "triangles_per_ray");
    row.rebuild_ms_mean = number_or_nan(r, "rebuild_ms_mean"), row.total_ms_mean = number_or_nan(r, "total_ms_mean");
    return row;
}

}  // namespace

std::vector<BenchScene> measure_bench(const std::vector<std::string>& scenes, const BenchOptions& o) {
    if (std::count(o.layouts.begin(), o.layouts.end(), "compressed") && std::count(o.tracers.begin(), o.tracers.end(), "stream"))
        throw std::invalid_argument("--layout compressed: the single-ray tracer only, not --tracer stream");
    const auto load = [&](const std::string& scene) -> SceneWork {
        BenchOptions one = o;
        one.scene = scene;
        const std::shared_ptr<LoadedScene> loaded = load_bench_scene(one);
        return [one, loaded](SceneReport& out) { return bench_scene(one, *loaded, out); };
    };
    std::vector<BenchScene> results;
    for (nlohmann::json& json : run_per_scene(scenes, load)) {
        BenchScene& scene = results.emplace_back(BenchScene{json.at("scene").get<std::string>(), {}, {}});
        for (const nlohmann::json& row : json.at("results")) scene.rows.push_back(bench_row(row));
        scene.json = std::move(json);
    }
    return results;
}

nlohmann::json bench_json(const std::vector<BenchScene>& scenes) {
    nlohmann::json all = nlohmann::json::array();
    for (const BenchScene& scene : scenes) all.push_back(scene.json);
    return all;
}

void run_bench(const std::vector<std::string>& scenes, const BenchOptions& o) {
    const std::vector<BenchScene> results = measure_bench(scenes, o);
    distributed::checked([&] {
        if (!distributed::is_root()) return;
        write_json(results.size() == 1 ? results[0].json : nlohmann::json{{"scenes", bench_json(results)}}, o.json_path);
    });
}

void run_bench(const BenchOptions& o) { run_bench({o.scene}, o); }

}  // namespace canopy
