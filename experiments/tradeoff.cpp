#include "experiments/tradeoff.h"
#include "base/output_path.h"
#include "experiments/embree_accelerator.h"

#include "renderer/frames.h"
#include "renderer/distributed.h"
#include "renderer/sample_sum.h"
#include "renderer/image.h"
#include "accel/builder.h"
#include "engine/options.h"
#include "experiments/command.h"
#include "experiments/plot.h"
#include "renderer/progress.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <stdexcept>

namespace canopy {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// The reference uses frame indices far from the measured ones, so its noise is independent of theirs.
constexpr uint32_t kReferenceFrameBase = 1u << 24;
// Error levels of the table: the first frame's error of the first row, then halvings (about 1, 4, 16, 64 frames).
constexpr int kLevels = 4;

struct Sample {
    int frames;
    double seconds;  // build + frames, wall time
    double rmse;
};

struct Curve {
    std::string label;
    double build_ms = 0;
    std::vector<Sample> samples;

    std::optional<double> seconds_to(double level) const {
        for (const Sample& s : samples)
            if (s.rmse <= level) return s.seconds;
        return std::nullopt;
    }
};

// The workload the reference is rendered with: nee where the curves compare it with diffuse (the same image, with
// less noise), else the one workload.
std::string reference_workload(const TradeoffOptions& o) {
    return std::count(o.workloads.begin(), o.workloads.end(), "nee") ? "nee" : o.workloads.front();
}

std::string reference_path(const TradeoffOptions& o) {
    std::string key = o.scene + "|" + std::to_string(o.width) + "x" + std::to_string(o.height) + "|" +
                      std::to_string(o.bounces) + "|" + std::to_string(o.reference_spp) + "|" + std::to_string(o.material_albedo);
    const std::string workload = reference_workload(o);
    if (workload != "diffuse") key += "|" + workload;  // diffuse references cached before workloads keep their names
    if (workload == "ao") key += "|" + std::to_string(o.workload.ao_rays) + "|" + std::to_string(o.workload.ao_length);
    char hash[17];
    std::snprintf(hash, sizeof hash, "%016zx", std::hash<std::string>{}(key));
    return o.output + ".reference-" + std::to_string(o.reference_spp) + "spp-" + hash + ".exr";
}

// The reference, rendered once and cached beside the outputs. Under a job of several ranks its samples are split
// between them (sample_sum.h); rank 0 decides whether the cache holds it, and alone returns it.
std::vector<float> converged_reference(const TradeoffOptions& o, const FlatScene& flat, const ShadingScene& shading,
                                       const PinholeCamera& camera) {
    const std::string path = reference_path(o);
    if (distributed::broadcast_from_root(std::filesystem::exists(path))) {
        if (!distributed::is_root()) return {};
        std::printf("reference: %s (cached)\n", path.c_str());
        return read_exr(path, o.width, o.height);
    }
    if (distributed::is_root()) std::printf("reference: rendering %d spp with binned SAH into %s\n", o.reference_spp, path.c_str());
    std::unique_ptr<Accelerator> accel;
    distributed::checked([&] {
        accel = make_canopy_accelerator(flat, {"binned", "", o.kernel});
        accel->prepare();
        accel->build();
    });
    const std::string what = "tradeoff " + o.scene + ": reference, spp ";
    const auto done = [&](float fraction) {
        return what + std::to_string(int(fraction * float(o.reference_spp))) + " of " + std::to_string(o.reference_spp);
    };
    const auto on_progress = [&](float fraction) { progress::update(done(fraction)); };
    if (progress::shown()) progress::phase(done(0.0f));
    const SampledImage image = render_samples(*accel, shading, camera, kReferenceFrameBase, o.reference_spp,
                                              progress::shown() ? on_progress : std::function<void(float)>());
    if (progress::shown()) on_progress(1.0f);  // the tiles' reports may arrive out of order: the last may not be all
    progress::finish();
    std::vector<float> reference;
    distributed::checked([&] {
        if (!distributed::is_root()) return;
        reference = image.sums.average(o.reference_spp);
        write_image(path, o.width, o.height, reference);
    });
    return reference;
}

Curve measure(Accelerator& accel, const TradeoffOptions& o, const ShadingScene& shading, const PinholeCamera& camera,
              const std::vector<float>& reference, bool name_workload) {
    Image image(o.width, o.height);
    const std::string what = "tradeoff " + o.scene + ", " +
                             (accel.library() == "embree" ? "embree " + accel.quality() : accel.builder()) + ": ";
    progress::phase(what + "building");
    auto start = Clock::now();
    accel.prepare();
    accel.build();
    double elapsed = seconds_since(start);
    const std::string chosen = accel.chosen().empty() ? "" : "(" + accel.chosen() + ")";  // auto's choice
    Curve curve{accel.library() == "embree" ? "embree " + accel.quality() : accel.builder() + chosen + " " + accel.kernel()};
    if (name_workload) curve.label += std::string(" ") + workload_name(shading.settings.workload);
    curve.build_ms = 1e3 * elapsed;
    // At least one frame, even when the build alone used the budget: a curve needs a point.
    for (int frame = 1; frame <= o.max_frames && (frame == 1 || elapsed < o.seconds); ++frame) {
        start = Clock::now();
        render(accel, shading, camera, uint32_t(frame), image);
        elapsed += seconds_since(start);
        curve.samples.push_back({frame, elapsed, rms_error(image.average(frame), reference, o.width, o.height)});
        if (progress::shown()) {
            char seconds[64];
            std::snprintf(seconds, sizeof seconds, " frames, %.1f of %g s", elapsed, o.seconds);
            progress::update(what + std::to_string(frame) + seconds);
        }
    }
    progress::finish();  // before the curve's line, on stdout
    return curve;
}

std::vector<double> error_levels(const std::vector<Curve>& curves) {
    std::vector<double> levels;
    for (int k = 0; k < kLevels && !curves.empty() && !curves[0].samples.empty(); ++k)
        levels.push_back(curves[0].samples[0].rmse * std::pow(0.5, k));
    return levels;
}

void print_table(const std::vector<Curve>& curves, const std::vector<double>& levels) {
    std::printf("\n%-22s %10s %10s %8s %10s", "accelerator", "build ms", "frame ms", "frames", "final RMSE");
    for (double level : levels) std::printf("  t(RMSE<=%.4f)", level);
    std::printf("\n");
    for (const Curve& c : curves) {
        const Sample& last = c.samples.back();
        std::printf("%-22s %10.1f %10.1f %8d %10.5f", c.label.c_str(), c.build_ms,
                    1e3 * (last.seconds - c.build_ms / 1e3) / last.frames, last.frames, last.rmse);
        for (double level : levels) {
            const auto t = c.seconds_to(level);
            if (t) std::printf("  %13.3fs", *t);
            else std::printf("  %14s", "-");
        }
        std::printf("\n");
    }
    std::printf("levels: the first row's 1-frame RMSE, then halvings (about 1, 4, 16, 64 frames); '-' not reached\n");
}

void write_outputs(const std::vector<Curve>& curves, const std::vector<double>& levels, const TradeoffOptions& o) {
    nlohmann::json rows = nlohmann::json::array();
    std::ofstream csv(o.output + ".csv");
    csv << "accelerator,frames,seconds,rmse\n";
    LogLogPlot plot{"time to image against error: " + o.scene, "seconds since the build started (build included)",
                    "RMSE against the reference", {}};
    for (const Curve& c : curves) {
        nlohmann::json samples = nlohmann::json::array(), reach = nlohmann::json::array();
        PlotSeries series{c.label, {}};
        for (const Sample& s : c.samples) {
            samples.push_back({{"frames", s.frames}, {"seconds", s.seconds}, {"rmse", s.rmse}});
            csv << c.label << "," << s.frames << "," << s.seconds << "," << s.rmse << "\n";
            series.points.push_back({s.seconds, s.rmse});
        }
        for (double level : levels) {
            const auto t = c.seconds_to(level);
            reach.push_back({{"rmse", level}, {"seconds", t ? nlohmann::json(*t) : nlohmann::json(nullptr)}});
        }
        rows.push_back({{"accelerator", c.label}, {"build_ms", c.build_ms}, {"samples", samples}, {"time_to_level", reach}});
        plot.series.push_back(std::move(series));
    }
    if (!csv) throw std::runtime_error(o.output + ".csv: cannot write");
    std::ofstream json(o.output + ".json");
    json << nlohmann::json{{"scene", o.scene}, {"width", o.width}, {"height", o.height}, {"bounces", o.bounces},
                           {"workloads", o.workloads}, {"reference_workload", reference_workload(o)},
                           {"reference_spp", o.reference_spp}, {"seconds", o.seconds}, {"results", rows}}.dump(2) << "\n";
    if (!json) throw std::runtime_error(o.output + ".json: cannot write");
    write_plot_png(plot, o.output + ".png");
    std::printf("wrote %s.json, %s.csv, %s.png\n", o.output.c_str(), o.output.c_str(), o.output.c_str());
}

// Curves of several workloads share one reference: they must converge to one image.
void check_same_image(const TradeoffOptions& o, const FlatScene& flat) {
    for (const std::string& w : o.workloads)
        if (w != "diffuse" && w != "nee")
            throw std::invalid_argument("--workload " + w + ": converges to an image of its own; several workloads compare "
                                        "diffuse and nee alone");
    if (!o.material_albedo || !flat.has_emitters)
        throw std::invalid_argument("--workload diffuse,nee: nee converges to diffuse's image only with the scene's emitters as "
                                    "lights (--materials, a scene with emission); under the sky alone it adds a sun");
}

}  // namespace

// Under a job of several ranks, they share the reference's samples; the curves, which time one process, are
// rank 0's alone.
void run_tradeoff(const TradeoffOptions& o) {
    const auto settings_of = [&](const std::string& workload) {
        FrameSettings settings;
        settings.width = o.width, settings.height = o.height, settings.max_bounces = o.bounces;
        settings.material_albedo = o.material_albedo;
        WorkloadOptions w = o.workload;
        w.workload = workload;
        w.apply(settings);
        return settings;
    };
    const FrameSettings settings = settings_of(o.workloads.front());
    Scene scene;
    FlatScene flat;
    std::vector<std::unique_ptr<Accelerator>> accels;  // made first, so bad names fail before any rendering
    distributed::checked([&] {
        scene = load_scene(o.scene);
        flat = flatten(scene);
        for (const std::string& builder : o.builders) {
            CanopyOptions options{builder, "", o.kernel};
            if (builder == "auto") options.auto_sample = frame_sample(scene, flat, settings);  // the curve's own frames
            accels.push_back(make_canopy_accelerator(scene, flat, options));
        }
        for (const std::string& quality : o.embree_qualities) accels.push_back(make_embree_accelerator(flat, quality, 0));
    });
    if (o.workloads.size() > 1) check_same_image(o, flat);
    const PinholeCamera camera(scene_camera(scene, flat), o.width, o.height);
    const FrameSettings reference_settings = settings_of(reference_workload(o));
    const std::vector<float> reference = converged_reference(o, flat, ShadingScene{flat, reference_settings}, camera);
    if (!distributed::is_root()) return;

    std::vector<FrameSettings> workload_settings;
    for (const std::string& workload : o.workloads) workload_settings.push_back(settings_of(workload));
    std::vector<Curve> curves;
    for (const auto& accel : accels)
        for (const FrameSettings& s : workload_settings) {
        curves.push_back(measure(*accel, o, ShadingScene{flat, s}, camera, reference, o.workloads.size() > 1));
        std::printf("%-22s %d frames in %.2f s, RMSE %.5f\n", curves.back().label.c_str(), curves.back().samples.back().frames,
                    curves.back().samples.back().seconds, curves.back().samples.back().rmse);
        }
    const std::vector<double> levels = error_levels(curves);
    print_table(curves, levels);
    write_outputs(curves, levels, o);
}

void register_tradeoff(CLI::App& canopy) {
    struct Parsed {
        TradeoffOptions options;
        std::vector<std::string> accels;
        std::vector<int> size{options.width, options.height};
        int threads = 0;
        bool quiet = false;
    };
    auto p = std::make_shared<Parsed>();
    TradeoffOptions& tr = p->options;
    CLI::App* tradeoff = canopy.add_subcommand("tradeoff", "Time to image against RMSE per builder, against a converged reference");
    tradeoff->add_option("scene", tr.scene, "Scene: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    tradeoff->add_option("--builder", tr.builders, "Builders: " + builder_names())->delimiter(',')->capture_default_str();
    tradeoff->add_option("--kernel", tr.kernel, "Kernel: auto (widest), bvh2, bvh4, bvh8")->capture_default_str();
    tradeoff->add_option("--accel", p->accels, "Also Embree, at the --embree-quality levels")->delimiter(',')
        ->check(CLI::IsMember({"embree"}));
    tradeoff->add_option("--embree-quality", tr.embree_qualities, "Embree qualities: low, medium, high")->delimiter(',')
        ->check(CLI::IsMember({"low", "medium", "high"}));
    tradeoff->add_option("--seconds", tr.seconds, "Wall time per builder, build included")->check(CLI::Range(0.001, 1e6))->capture_default_str();
    tradeoff->add_option("--max-frames", tr.max_frames, "Frames per builder at most")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    tradeoff->add_option("--reference-spp", tr.reference_spp, "Samples of the cached reference")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    tradeoff->add_option("--size", p->size, "Width and height")->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    tradeoff->add_option("--bounces", tr.bounces, "Maximum bounces")->check(CLI::Range(0, 1024))->capture_default_str();
    tradeoff->add_option("--workload", tr.workloads, std::string(kWorkloadHelp) + "; a curve each")
        ->delimiter(',')
        ->check(CLI::IsMember({"diffuse", "camera", "nee", "ao"}))
        ->capture_default_str();
    tradeoff->add_option("--ao-rays", tr.workload.ao_rays, "ao: occlusion rays from each camera hit")->check(CLI::Range(1, 1024));
    tradeoff->add_option("--ao-length", tr.workload.ao_length, "ao: their length (default: a tenth of the scene box's diagonal)")
        ->check(CLI::PositiveNumber);
    tradeoff->add_flag("--materials", tr.material_albedo, "Use the materials: Kd or baseColorFactor as albedo, Ke or emissiveFactor as light");
    tradeoff->add_option("-o,--output", tr.output, "Output stem: STEM.json, STEM.csv, STEM.png, cached reference beside")->capture_default_str();
    tradeoff->add_option("--threads", p->threads, "Threads for every library (0: all)")->check(CLI::Range(0, 4096));
    tradeoff->add_flag("--quiet", p->quiet, kQuietHelp);
    tradeoff->callback([p] {
        TradeoffOptions& o = p->options;
        o.width = p->size[0], o.height = p->size[1];
        o.builders = join_builder_specs(o.builders);
        if (p->accels.empty()) o.embree_qualities.clear();
        else if (o.embree_qualities.empty()) o.embree_qualities = {"medium"};
        // The stem's first file stands for all four: they share its folder.
        distributed::checked([&] { if (distributed::is_root()) check_output_path("-o", o.output + ".json"); });
        const auto limit = limit_threads(p->threads);
        progress::start(p->quiet);
        run_tradeoff(o);
    });
}

}  // namespace canopy
