#include "experiments/study.h"

#include "experiments/plot.h"
#include "base/output_path.h"

#include "accel/builder.h"
#include "renderer/frames.h"
#include "renderer/recorded_rays.h"
#include "renderer/distributed.h"
#include "engine/options.h"
#include "experiments/per_scene.h"
#include "renderer/progress.h"

#include <CLI/CLI.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <tuple>

namespace canopy {

std::optional<double> pearson(const std::vector<double>& x, const std::vector<double>& y) {
    const double n = double(x.size());
    double mx = 0, my = 0;
    for (size_t i = 0; i < x.size(); ++i) mx += x[i] / n, my += y[i] / n;
    double sxy = 0, sxx = 0, syy = 0;
    for (size_t i = 0; i < x.size(); ++i) {
        sxy += (x[i] - mx) * (y[i] - my), sxx += (x[i] - mx) * (x[i] - mx), syy += (y[i] - my) * (y[i] - my);
    }
    if (sxx <= 0 || syy <= 0) return std::nullopt;
    return sxy / std::sqrt(sxx * syy);
}

namespace {

// Sec. 4.4: 45 degrees about the (1, 1, 1) axis, here through the scene's centre so the scene stays in view.
struct Rotation {
    glm::mat3 turn = glm::mat3(glm::rotate(glm::mat4(1.0f), glm::radians(45.0f), glm::normalize(Vec3(1.0f))));
    Vec3 pivot;

    Vec3 point(const Vec3& p) const { return pivot + turn * (p - pivot); }
    Ray ray(const Ray& r) const { return {point(r.org), turn * r.dir, r.tmin, r.tmax}; }
    FlatScene scene(const FlatScene& flat) const {
        FlatScene rotated = flat;
        rotated.bounds = BBox{};
        for (Triangle& t : rotated.triangles) {
            t = {point(t.v0), point(t.v1), point(t.v2)};
            rotated.bounds.extend(BBox::of(t));
        }
        return rotated;
    }
};

// The fastest of `repeats` passes.
double ns_per_ray(const Accelerator& accel, const std::vector<Ray>& rays, int repeats) {
    double best = std::numeric_limits<double>::infinity();
    for (int r = 0; r < repeats; ++r) best = std::min(best, pass_ns_per_ray(accel, rays));
    return best;
}

// The fastest of `repeats` passes of each, a pass of one then a pass of the other, so that both see the same
// machine load: for differences of a few percent.
std::pair<double, double> alternating_ns_per_ray(const Accelerator& a, const Accelerator& b, const std::vector<Ray>& rays,
                                                 int repeats) {
    double best_a = std::numeric_limits<double>::infinity(), best_b = best_a;
    for (int r = 0; r < repeats; ++r) {
        best_a = std::min(best_a, pass_ns_per_ray(a, rays));
        best_b = std::min(best_b, pass_ns_per_ray(b, rays));
    }
    return {best_a, best_b};
}

// (1 - alpha - beta) SAH + alpha EPO + beta LCV: eq. 7, and eq. 6 with beta = 0.
std::vector<double> predicted(const std::vector<StudyRow>& rows, bool scalar, double alpha, double beta) {
    std::vector<double> p;
    for (const StudyRow& r : rows)
        p.push_back(scalar ? (1 - alpha) * r.scalar_sah + alpha * r.scalar_epo
                           : (1 - alpha - beta) * r.sah + alpha * r.epo + beta * r.lcv);
    return p;
}

// The rows the fits are over: the BVHs'. Another structure family's rows (the kd-tree) are measured and listed,
// but have no EPO or wide layout, and its SAH sums voxel areas, not the triangles' bounds.
std::vector<StudyRow> bvh_rows(const std::vector<StudyRow>& rows) {
    std::vector<StudyRow> out;
    for (const StudyRow& r : rows)
        if (is_bvh_builder(spec_name(r.builder))) out.push_back(r);
    return out;
}

std::vector<double> measured(const std::vector<StudyRow>& rows, bool scalar) {
    std::vector<double> m;
    for (const StudyRow& r : rows) m.push_back(scalar ? r.scalar_ns : r.simd_ns);
    return m;
}

constexpr int kGridSteps = 100;  // alpha and beta in steps of 0.01

// The weights of eq. 6 (with_lcv false) or eq. 7 that maximise the correlation, over a 0.01 grid.
StudyFit best_fit(const std::vector<StudyRow>& rows, bool scalar, bool with_lcv) {
    StudyFit best;
    for (int a = 0; a <= kGridSteps; ++a)
        for (int b = 0; b <= (with_lcv ? kGridSteps - a : 0); ++b) {
            const double alpha = a / double(kGridSteps), beta = b / double(kGridSteps);
            const auto c = pearson(predicted(rows, scalar, alpha, beta), measured(rows, scalar));
            if (c && (!best.correlation || *c > *best.correlation)) best = {alpha, beta, c};
        }
    return best;
}

std::string corr(const std::optional<double>& c) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3f", c ? *c : std::nan(""));
    return c ? text : "  -  ";
}

nlohmann::json json_or_null(const std::optional<double>& c) { return c ? nlohmann::json(*c) : nlohmann::json(nullptr); }

// Table 2's fixed parameters: the (alpha, beta) with the best average correlation over all scenes.
StudyFit fixed_fit(const std::vector<StudyScene>& results, bool scalar, bool with_lcv) {
    StudyFit best;
    for (int a = 0; a <= kGridSteps; ++a)
        for (int b = 0; b <= (with_lcv ? kGridSteps - a : 0); ++b) {
            double sum = 0;
            int counted = 0;
            for (const StudyScene& s : results)
                if (auto c = pearson(predicted(bvh_rows(s.rows), scalar, a / double(kGridSteps), b / double(kGridSteps)),
                                     measured(bvh_rows(s.rows), scalar)))
                    sum += *c, ++counted;
            if (counted && (!best.correlation || sum / counted > *best.correlation))
                best = {a / double(kGridSteps), b / double(kGridSteps), sum / counted};
        }
    return best;
}

// The tables' name columns: as wide as their longest name, so that long scene specs and builder names do not
// shift the columns after them.
struct NameWidths {
    int scene = 34, builder = 10;
};

int widest(int least, const std::string& name) { return std::max(least, int(name.size())); }

NameWidths name_widths(const std::vector<StudyScene>& results) {
    NameWidths w;
    for (const StudyScene& s : results) {
        w.scene = widest(w.scene, s.scene);
        for (const StudyRow& r : s.rows) w.builder = widest(w.builder, r.builder);
    }
    return w;
}

void print_tables(const std::vector<StudyScene>& results, const StudyFit& fixed_scalar, const StudyFit& fixed_simd) {
    const int w = name_widths(results).scene;
    std::printf("\nTable 1: per-scene correlation of predicted cost with measured ns/ray (Pearson, eq. 5)\n");
    std::printf("%-*s %9s | %7s %14s | %7s %14s %20s\n", w, "scene", "builders", "scalar", "scalar", "SIMD", "SIMD", "SIMD");
    std::printf("%-*s %9s | %7s %14s | %7s %14s %20s\n", w, "", "", "SAH", "SAH+EPO (a)", "SAH", "SAH+EPO (a)", "SAH+EPO+LCV (a,b)");
    for (const StudyScene& s : results)
        std::printf("%-*s %9zu | %7s %7s (%.2f) | %7s %7s (%.2f) %11s (%.2f,%.2f)\n", w, s.scene.c_str(), s.rows.size(),
                    corr(s.scalar_sah).c_str(), corr(s.scalar_epo.correlation).c_str(), s.scalar_epo.alpha,
                    corr(s.simd_sah).c_str(), corr(s.simd_epo.correlation).c_str(), s.simd_epo.alpha,
                    corr(s.simd_lcv.correlation).c_str(), s.simd_lcv.alpha, s.simd_lcv.beta);
    auto summary = [&](const char* name, auto get) {
        double sum = 0, low = 1;
        int n = 0;
        for (const StudyScene& s : results)
            if (auto c = get(s)) sum += *c, low = std::min(low, *c), ++n;
        if (n) std::printf("  %-34s average %.3f, minimum %.3f over %d scenes\n", name, sum / n, low, n);
    };
    std::printf("\nTable 2: aggregate correlations\n");
    summary("scalar SAH", [](const StudyScene& s) { return s.scalar_sah; });
    summary("scalar SAH+EPO (per-scene a)", [](const StudyScene& s) { return s.scalar_epo.correlation; });
    summary("SIMD SAH", [](const StudyScene& s) { return s.simd_sah; });
    summary("SIMD SAH+EPO (per-scene a)", [](const StudyScene& s) { return s.simd_epo.correlation; });
    summary("SIMD SAH+EPO+LCV (per-scene a,b)", [](const StudyScene& s) { return s.simd_lcv.correlation; });
    std::printf("  fixed over all scenes: scalar SAH+EPO a = %.2f (average %s); SIMD SAH+EPO+LCV a = %.2f, b = %.2f (average %s)\n",
                fixed_scalar.alpha, corr(fixed_scalar.correlation).c_str(), fixed_simd.alpha, fixed_simd.beta,
                corr(fixed_simd.correlation).c_str());
}

double percent_change(double after, double before) { return 100.0 * (after / before - 1.0); }

// The change signed, with one decimal and a percent sign, right-aligned in `width`, or "-" where a structure family
// does not define the metric (NaN).
std::string change_text(double percent, int width) {
    char text[32];
    if (std::isnan(percent)) std::snprintf(text, sizeof text, "%*s", width, "-");
    else std::snprintf(text, sizeof text, "%+*.1f%%", width - 1, percent);
    return text;
}

// Sec. 4.4's composite estimate: eq. 6 with the paper's average SIMD alpha (0.50), on costs relative to the
// unrotated tree's, so that SAH and EPO weigh by their change, not their scale.
constexpr double kPaperSimdAlpha = 0.50;
double composite_change(const StudyRow& r) {
    return 100.0 * ((1.0 - kPaperSimdAlpha) * r.rotated_sah / r.sah + kPaperSimdAlpha * r.rotated_epo / r.epo - 1.0);
}

// Sec. 4.4: what rotating scene and rays 45 degrees about (1, 1, 1) costs each builder, measured and predicted.
void print_rotation_table(const std::vector<StudyScene>& results) {
    const NameWidths w = name_widths(results);
    std::printf("\nSec. 4.4: scene and rays rotated 45 degrees about (1, 1, 1), change against the unrotated tree\n");
    std::printf("%-*s %-*s %10s %8s %8s %8s %11s\n", w.scene, "scene", w.builder, "builder", "SIMD time", "SAH", "EPO", "LCV",
                "eq. 6 a=.5");
    double time = 0, sah = 0, epo = 0, composite = 0;
    int n = 0;
    for (const StudyScene& s : results)
        for (const StudyRow& r : s.rows) {
            if (std::isnan(r.rotated_ns)) continue;
            std::printf("%-*s %-*s %s %s %s %s %s\n", w.scene, s.scene.c_str(), w.builder, r.builder.c_str(),
                        change_text(percent_change(r.rotated_ns, r.simd_ns), 10).c_str(),
                        change_text(percent_change(r.rotated_sah, r.sah), 8).c_str(),
                        change_text(percent_change(r.rotated_epo, r.epo), 8).c_str(),
                        change_text(percent_change(r.rotated_lcv, r.lcv), 8).c_str(), change_text(composite_change(r), 11).c_str());
            if (!is_bvh_builder(spec_name(r.builder))) continue;  // the averages are the paper's, over BVHs
            time += percent_change(r.rotated_ns, r.simd_ns), sah += percent_change(r.rotated_sah, r.sah);
            epo += percent_change(r.rotated_epo, r.epo), composite += composite_change(r), ++n;
        }
    if (!n) return;
    std::printf("%-*s %+9.1f%% %+7.1f%% %+7.1f%% %8s %+10.1f%%\n", w.scene + 1 + w.builder, "average over BVHs", time / n,
                sah / n, epo / n, "",
                composite / n);
    std::printf("paper (22 scenes, GPU SIMD): time +168%% (+90%% SBVH and STreelet, +250%% Agglo), SAH under +10%% for "
                "SBVH and STreelet and +50%% for the others, EPO +290%%, eq. 6 with a = 0.50 +165%%\n");
}

// Sec. 6: the same trees with their nodes shuffled in memory.
void print_permutation_table(const std::vector<StudyScene>& results) {
    std::printf("\nSec. 6: wide nodes permuted at random in memory, SIMD time against the builder's own node order (timed "
                "alternately)\n");
    const NameWidths w = name_widths(results);
    std::printf("%-*s %-*s %10s %10s %10s\n", w.scene, "scene", w.builder, "builder", "ns/ray", "permuted", "change");
    double sum = 0;
    int n = 0;
    for (const StudyScene& s : results)
        for (const StudyRow& r : s.rows) {
            if (std::isnan(r.permuted_ns)) continue;
            std::printf("%-*s %-*s %10.1f %10.1f %+9.1f%%\n", w.scene, s.scene.c_str(), w.builder, r.builder.c_str(), r.unpermuted_ns,
                        r.permuted_ns, percent_change(r.permuted_ns, r.unpermuted_ns));
            sum += percent_change(r.permuted_ns, r.unpermuted_ns), ++n;
        }
    if (!n) return;
    std::printf("%-*s %21s %+9.1f%%\n", w.scene + 1 + w.builder, "average", "", sum / n);
    std::printf("paper (GPU): under 1%% change\n");
}

// One panel per scene: each builder's predicted SIMD cost (eq. 7 with the scene's fitted a and b) against its
// measured SIMD ns/ray, with the least-squares line; the nearer the points lie to it, the better the metric.
void write_plot(const std::vector<StudyScene>& results, const std::string& path) {
    ScatterPlot plot{"predicted cost (eq. 7)", "measured SIMD ns/ray", {}};
    for (const StudyScene& s : results) {
        const std::vector<StudyRow> rows = bvh_rows(s.rows);
        const std::vector<double> p = predicted(rows, false, s.simd_lcv.alpha, s.simd_lcv.beta);
        const std::vector<double> m = measured(rows, false);
        char fit[96];
        std::snprintf(fit, sizeof fit, "Pearson r = %s at a = %.2f, b = %.2f", corr(s.simd_lcv.correlation).c_str(),
                      s.simd_lcv.alpha, s.simd_lcv.beta);
        ScatterPanel panel{s.scene, fit, {}};
        for (size_t i = 0; i < rows.size(); ++i) panel.points.push_back({p[i], m[i], rows[i].builder});
        plot.panels.push_back(std::move(panel));
    }
    write_scatter_png(plot, path);
}

}  // namespace

double leaf_count_variability(const Accelerator& accel, const std::vector<Ray>& rays) {
    double sum = 0, sum2 = 0;
    for (const Ray& ray : rays) {
        const double leaves = double(accel.count(ray).leaf_nodes);
        sum += leaves, sum2 += leaves * leaves;
    }
    const double mean = sum / double(rays.size());
    return std::sqrt(std::max(0.0, sum2 / double(rays.size()) - mean * mean));
}

namespace {

nlohmann::json row_json(const StudyRow& r) {
    return {{"builder", r.builder}, {"host", r.host}, {"sah", r.sah}, {"epo", r.epo}, {"lcv", r.lcv},
            {"scalar_ns_per_ray", r.scalar_ns}, {"simd_ns_per_ray", r.simd_ns},
            {"scalar_sah", r.scalar_sah}, {"scalar_epo", r.scalar_epo},
            {"wide_sah", r.wide_sah}, {"wide_epo", r.wide_epo},
            {"rotated_sah", r.rotated_sah}, {"rotated_epo", r.rotated_epo}, {"rotated_lcv", r.rotated_lcv},
            {"rotated_simd_ns_per_ray", r.rotated_ns}, {"permuted_simd_ns_per_ray", r.permuted_ns},
            {"unpermuted_simd_ns_per_ray", r.unpermuted_ns}};
}

// The study reproduces the quality-metrics paper (Aila, Karras and Laine 2013): its SBVH at the paper's alpha, and
// every builder's binary tree, whose metrics it measures, collapsed (lbvh's too, whose default has no binary tree).
CanopyOptions study_options(const std::string& builder, const std::string& kernel) {
    CanopyOptions options{builder == "sbvh" ? "sbvh:alpha=1e-5" : builder, "", kernel};
    options.collapse = CollapseMethod::Optimal;
    return options;
}

// JSON writes a NaN as null: read it back as one.
double number(const nlohmann::json& j, const char* key) {
    return j.at(key).is_null() ? std::nan("") : j.at(key).get<double>();
}

StudyRow row_from_json(const nlohmann::json& j) {
    return {j.at("builder"), j.at("host"), number(j, "scalar_sah"), number(j, "scalar_epo"), number(j, "scalar_ns_per_ray"),
            number(j, "sah"), number(j, "epo"), number(j, "lcv"), number(j, "simd_ns_per_ray"), number(j, "wide_sah"),
            number(j, "wide_epo"), number(j, "rotated_sah"), number(j, "rotated_epo"), number(j, "rotated_lcv"),
            number(j, "rotated_simd_ns_per_ray"), number(j, "permuted_simd_ns_per_ray"),
            number(j, "unpermuted_simd_ns_per_ray")};
}

// Sec. 4.4: the row's builder on the rotated scene, its SIMD tree timed with the rotated rays.
void measure_rotated(StudyRow& row, const FlatScene& rotated, const std::vector<Ray>& rays, const StudyOptions& o,
                     int name_width, SceneReport& report) {
    auto simd = make_canopy_accelerator(rotated, study_options(row.builder, "auto"));
    simd->prepare(), simd->build();
    const AcceleratorReport r = simd->report(true);
    row.rotated_sah = r.sah.value_or(std::nan("")), row.rotated_epo = r.epo.value_or(std::nan(""));
    row.rotated_lcv = leaf_count_variability(*simd, rays);
    row.rotated_ns = ns_per_ray(*simd, rays, o.repeats);
    report.printf("  %-*s rotated 45 degrees about (1, 1, 1): SAH %7.2f EPO %7.2f LCV %6.2f %7.1f ns/ray\n",
                  name_width, row.builder.c_str(), row.rotated_sah, row.rotated_epo, row.rotated_lcv, row.rotated_ns);
}

// Sec. 6: the row's SIMD tree again, its nodes shuffled in memory, timed with the same rays alternately with
// `original`.
void measure_permuted(StudyRow& row, const Accelerator& original, const FlatScene& flat, const std::vector<Ray>& rays,
                      const StudyOptions& o, int name_width, SceneReport& report) {
    CanopyOptions options = study_options(row.builder, "auto");
    options.permute_nodes = o.permute_seed;
    auto permuted = make_canopy_accelerator(flat, options);
    permuted->prepare(), permuted->build();
    std::tie(row.unpermuted_ns, row.permuted_ns) = alternating_ns_per_ray(original, *permuted, rays, o.repeats);
    report.printf("  %-*s nodes permuted in memory (seed %llu): %7.1f ns/ray against %.1f in the builder's order\n",
                  name_width, row.builder.c_str(), (unsigned long long)o.permute_seed, row.permuted_ns, row.unpermuted_ns);
}

// One scene's rows, every builder's trees built and timed in this process.
StudyScene study_scene(const std::string& scene_name, const Scene& scene, const FlatScene& flat,
                        const std::vector<std::string>& names, const StudyOptions& o, SceneReport& report) {
    const PinholeCamera camera(scene_camera(scene, flat), o.width, o.height);
    progress::phase("study " + scene_name + ": the reference tree and the diffuse rays");
    auto reference = make_canopy_accelerator(flat, {"binned", "", "auto"});
    reference->prepare();
    reference->build();
    const std::vector<Ray> rays = diffuse_rays(*reference, flat, camera, o.width, o.height);
    report.printf("%s: %zu triangles, %zu diffuse rays (%dx%d, %d bounces)%s\n", scene_name.c_str(), flat.triangles.size(),
                  rays.size(), o.width, o.height, FrameSettings{}.max_bounces, distributed::where().c_str());
    StudyScene result{scene.name.empty() ? scene_name : scene.name, {}, {}, {}, {}, {}, {}};
    const Rotation rotation{.pivot = flat.bounds.center()};
    const std::optional<FlatScene> rotated = o.rotate ? std::optional(rotation.scene(flat)) : std::nullopt;
    std::vector<Ray> rotated_rays;
    if (o.rotate)
        for (const Ray& ray : rays) rotated_rays.push_back(rotation.ray(ray));
    int name_width = 8;
    for (const std::string& name : names) name_width = widest(name_width, name);
    for (const std::string& name : names) {
        const std::string what = "study " + scene_name + ", " + name + ": ";
        progress::update(what + "building the scalar and SIMD trees");
        auto scalar = make_canopy_accelerator(flat, study_options(name, "bvh2"));
        auto simd = make_canopy_accelerator(flat, study_options(name, "auto"));
        for (Accelerator* a : {scalar.get(), simd.get()}) a->prepare(), a->build();
        progress::update(what + "SAH, EPO, LCV and timing the rays");
        const AcceleratorReport rs = scalar->report(true), rw = simd->report(true);
        const double none = std::nan("");  // what another structure family does not define (EPO, wide layouts)
        StudyRow row{name, distributed::host(), rs.sah.value_or(none), rs.epo.value_or(none), ns_per_ray(*scalar, rays, o.repeats),
                     rw.sah.value_or(none), rw.epo.value_or(none), leaf_count_variability(*simd, rays), ns_per_ray(*simd, rays, o.repeats),
                     rw.layout_sah.value_or(none), rw.layout_epo.value_or(none)};
        report.printf("  %-*s scalar: SAH %7.2f EPO %7.2f %7.1f ns/ray | %s: SAH %7.2f EPO %7.2f LCV %6.2f %7.1f ns/ray\n",
                      name_width, name.c_str(), row.scalar_sah, row.scalar_epo, row.scalar_ns, simd->kernel().c_str(), row.sah,
                      row.epo, row.lcv, row.simd_ns);
        if (rotated) {
            progress::update(what + "the rotated scene");
            measure_rotated(row, *rotated, rotated_rays, o, name_width, report);
        }
        if (o.permute_nodes && is_bvh_builder(spec_name(name))) {
            progress::update(what + "the permuted nodes");
            measure_permuted(row, *simd, flat, rays, o, name_width, report);
        }
        report.flush();  // a study takes minutes: show each row as it comes
        result.rows.push_back(row);
    }
    progress::finish();
    return result;
}

void fit(StudyScene& result) {
    const std::vector<StudyRow> rows = bvh_rows(result.rows);
    result.scalar_sah = pearson(predicted(rows, true, 0, 0), measured(rows, true));
    result.simd_sah = pearson(predicted(rows, false, 0, 0), measured(rows, false));
    result.scalar_epo = best_fit(rows, true, false);
    result.simd_epo = best_fit(rows, false, false);
    result.simd_lcv = best_fit(rows, false, true);
}

// Every scene's rows, on rank 0 (under a job, each scene measured by one rank: per_scene.h), and their fits.
std::vector<StudyScene> study_scenes(const std::vector<std::string>& names, const StudyOptions& o) {
    const auto load = [&](const std::string& scene_name) -> SceneWork {
        const auto scene = std::make_shared<const Scene>(load_scene(scene_name));
        const auto flat = std::make_shared<const FlatScene>(flatten(*scene));
        return [&, scene_name, scene, flat](SceneReport& report) {
            const StudyScene result = study_scene(scene_name, *scene, *flat, names, o, report);
            nlohmann::json rows = nlohmann::json::array();
            for (const StudyRow& r : result.rows) rows.push_back(row_json(r));
            return nlohmann::json{{"scene", result.scene}, {"rows", rows}};
        };
    };
    std::vector<StudyScene> results;
    for (const nlohmann::json& scene : run_per_scene(o.scenes, load)) {
        StudyScene& r = results.emplace_back();
        r.scene = scene.at("scene");
        for (const nlohmann::json& row : scene.at("rows")) r.rows.push_back(row_from_json(row));
        fit(r);
    }
    return results;
}

}  // namespace

nlohmann::json study_json(const StudyResult& result) {
    const StudyFit &fixed_scalar = result.fixed_scalar, &fixed_simd = result.fixed_simd;
    nlohmann::json scenes = nlohmann::json::array();
    for (const StudyScene& s : result.scenes) {
        nlohmann::json rows = nlohmann::json::array();
        for (const StudyRow& r : s.rows) rows.push_back(row_json(r));
        scenes.push_back({{"scene", s.scene}, {"builders", rows},
                          {"correlation", {{"sah", json_or_null(s.simd_sah)}, {"sah_epo", json_or_null(s.simd_epo.correlation)},
                                           {"sah_epo_alpha", s.simd_epo.alpha},
                                           {"sah_epo_lcv", json_or_null(s.simd_lcv.correlation)}}},
                          {"scalar_correlation", {{"sah", json_or_null(s.scalar_sah)},
                                                  {"sah_epo", json_or_null(s.scalar_epo.correlation)}, {"alpha", s.scalar_epo.alpha}}},
                          {"alpha", s.simd_lcv.alpha}, {"beta", s.simd_lcv.beta}});
    }
    return {{"scenes", scenes},
            {"fixed", {{"alpha", fixed_simd.alpha}, {"beta", fixed_simd.beta},
                       {"average_correlation", json_or_null(fixed_simd.correlation)},
                       {"scalar_alpha", fixed_scalar.alpha},
                       {"scalar_average_correlation", json_or_null(fixed_scalar.correlation)}}}};
}

namespace {

void report_study(const StudyResult& result, const StudyOptions& o) {
    const std::vector<StudyScene>& results = result.scenes;
    print_tables(results, result.fixed_scalar, result.fixed_simd);
    if (o.rotate) print_rotation_table(results);
    if (o.permute_nodes) print_permutation_table(results);
    if (!o.plot_path.empty()) write_plot(results, o.plot_path), std::printf("wrote %s\n", o.plot_path.c_str());
    if (o.json_path.empty()) return;
    std::ofstream out(o.json_path);
    out << study_json(result).dump(2) << "\n";
    if (!out) throw std::runtime_error(o.json_path + ": cannot write the study JSON");
    std::printf("wrote %s\n", o.json_path.c_str());
}

std::vector<std::string> builder_names_of(const StudyOptions& o) {
    std::vector<std::string> names = o.builders;
    if (names.empty())
        for (const BuilderEntry& b : builders()) names.push_back(b.name);
    return names;
}

}  // namespace

StudyResult measure_study(const StudyOptions& o) {
    StudyResult result;
    result.scenes = study_scenes(builder_names_of(o), o);
    distributed::checked([&] {
        if (!distributed::is_root()) return;
        result.fixed_scalar = fixed_fit(result.scenes, true, false), result.fixed_simd = fixed_fit(result.scenes, false, true);
        report_study(result, o);
    });
    return result;
}

void run_study(const StudyOptions& o) { measure_study(o); }

void register_study(CLI::App& canopy) {
    auto st = std::make_shared<StudyOptions>();
    struct Run {  // the command's, not the measurement's (reproduce runs studies too)
        int threads = 0;
        bool quiet = false;
    };
    auto run = std::make_shared<Run>();
    auto size = std::make_shared<std::vector<int>>(std::vector<int>{st->width, st->height});
    CLI::App* study = canopy.add_subcommand("study", "SAH, EPO and LCV against measured ns/ray for every builder (Aila et al. 2013)");
    study->add_option("scenes", st->scenes, "Scenes: scene.json, .obj, .gltf, .glb or gen:NAME?tris=N&seed=S")->required();
    study->add_option("--builder", st->builders, "Builders (default: every BVH builder): " + builder_names(false))->delimiter(',');
    study->add_option("--size", *size, "Width and height of the frame whose diffuse rays are timed")
        ->expected(2)->check(CLI::Range(1, 16384))->capture_default_str();
    study->add_option("--repeats", st->repeats, "Timing passes per tree (fastest kept)")->check(CLI::Range(1, 100))->capture_default_str();
    study->add_option("--json", st->json_path, "Write results as JSON");
    study->add_flag("--rotate", st->rotate, "Also each builder on the scene and rays rotated 45 degrees about (1, 1, 1) (sec. 4.4)");
    study->add_flag("--permute-nodes", st->permute_nodes, "Also each SIMD tree with its nodes shuffled in memory (sec. 6)");
    study->add_option("--permute-seed", st->permute_seed, "Seed of --permute-nodes' shuffle")->capture_default_str();
    study->add_option("--plot", st->plot_path, "Write a PNG: predicted (eq. 7) against measured SIMD ns/ray, a panel per scene");
    study->add_option("--threads", run->threads, "Threads for every library (0: all)")->check(CLI::Range(0, 4096));
    study->add_flag("--quiet", run->quiet, kQuietHelp);
    study->callback([st, size, run] {
        distributed::checked([&] {
            st->builders = join_builder_specs(st->builders);
            for (const std::string& b : st->builders) check_builder_name(b);  // unknown names fail before any work
            if (!distributed::is_root()) return;  // rank 0 writes the report
            if (!st->json_path.empty()) check_output_path("--json", st->json_path);
            if (!st->plot_path.empty()) check_output_path("--plot", st->plot_path, {".png"});
        });
        st->width = (*size)[0], st->height = (*size)[1];
        const auto limit = limit_threads(run->threads);
        progress::start(run->quiet);
        run_study(*st);
    });
}

}  // namespace canopy
