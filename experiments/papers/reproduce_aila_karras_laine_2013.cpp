// Aila, Karras and Laine 2013, "On quality metrics of bounding volume hierarchies": Table 1 (per scene, every
// builder's scalar and SIMD ns/ray, SAH, EPO and LCV, and how well eq. 6 and 7 predict the times), Table 2 (the
// correlations' average and minimum), sec. 4.3 (one fixed alpha and beta for all scenes), sec. 4.4 (scene and rays
// rotated 45 degrees about (1, 1, 1)) and sec. 6 (nodes permuted in memory), measured by `canopy study` with the
// paper's nine builders on CPU kernels: "scalar" is canopy's bvh2 kernel, "SIMD" its widest (bvh8 with AVX-512).
#include "experiments/papers/reproduce.h"
#include "experiments/study.h"
#include "renderer/distributed.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <stdexcept>

namespace canopy {
namespace {

// The paper's builders (Table 1's columns) and canopy's names for them.
constexpr PaperBuilder kBuilders[] = {{"LBVH", "lbvh"},     {"BBVH", "sweep"},        {"SBVH", "sbvh"},
                                 {"Agglo", "agglo"},   {"Bittner", "bittner"},   {"H.Climb", "hillclimb"},
                                 {"Anneal.", "anneal"}, {"Treelet", "treelet"}, {"STreelet", "streelet"}};
constexpr size_t kBuilderCount = std::size(kBuilders);

// A scene of Table 1 (NVIDIA GTX680, diffuse rays): per builder in kBuilders' order.
struct PaperScene {
    const char* name;
    double scalar_ns[kBuilderCount], simd_ns[kBuilderCount], sah[kBuilderCount], epo[kBuilderCount], lcv[kBuilderCount];
    double scalar_sah, scalar_epo, simd_sah, simd_epo, simd_lcv;  // correlations with ns/ray
};
constexpr PaperScene kConference{
    "CONFERENCE (282,755 triangles)",
    {111.36, 69.01, 56.85, 58.41, 55.90, 68.07, 55.16, 59.31, 55.01},
    {12.02, 5.97, 4.16, 5.81, 5.53, 6.15, 5.17, 5.56, 4.42},
    {71.89, 46.50, 38.94, 38.17, 36.51, 42.69, 36.24, 38.48, 39.32},
    {21.68, 9.79, 4.10, 8.27, 6.76, 11.51, 7.07, 8.21, 2.19},
    {11.66, 2.63, 1.35, 3.25, 3.30, 2.66, 2.40, 2.50, 1.38},
    0.992, 0.999, 0.951, 0.983, 0.998};
constexpr PaperScene kDragon{
    "DRAGON (869,928 triangles)",
    {95.97, 78.74, 77.10, 96.62, 82.37, 84.82, 93.98, 83.54, 81.90},
    {8.94, 6.83, 6.65, 8.49, 7.28, 7.46, 8.15, 7.52, 7.35},
    {71.97, 56.74, 55.75, 65.43, 57.26, 62.04, 63.28, 60.41, 59.22},
    {6.04, 3.29, 2.50, 11.35, 5.02, 5.00, 9.66, 5.00, 3.47},
    {2.65, 1.79, 1.76, 1.95, 1.88, 1.87, 1.84, 1.85, 1.78},
    0.896, 0.996, 0.959, 0.988, 0.990};

// Table 2 (22 scenes) and sec. 4.3.
struct Aggregate {
    const char* what;
    double average, minimum;
};
constexpr Aggregate kTable2[] = {{"scalar, SAH", 0.915, 0.652}, {"scalar, SAH+EPO (eq. 6)", 0.994, 0.988},
                                 {"SIMD, SAH", 0.933, 0.660},   {"SIMD, SAH+EPO (eq. 6)", 0.979, 0.907},
                                 {"SIMD, SAH+EPO+LCV (eq. 7)", 0.993, 0.988}};

constexpr PaperSubject<PaperScene> kSubjects[] = {
    {"conference", "conference", nullptr, &kConference},
    {"stanford-dragon-decimated", "stanford-dragon-decimated", nullptr, &kDragon},
    {"sibenik", "sibenik", nullptr},
    {"crytek-sponza", "crytek-sponza", nullptr},
    {"stanford-bunny", "stanford-bunny", "stanford-bunny"},
    {"armadillo-decimated", "armadillo-decimated", nullptr},
    {"cornell-box", nullptr, "cornell-box"},
};

const StudyRow* row_of(const StudyScene& scene, const char* builder) {
    for (const StudyRow& row : scene.rows)
        if (row.builder == builder) return &row;
    return nullptr;
}

double correlation(const std::optional<double>& c) { return c.value_or(kNotMeasured); }

// Table 1 for one scene: a line per metric, a column per builder, the paper's line under canopy's.
std::string table1(const StudyScene& scene, const PaperScene* paper) {
    struct Metric {
        const char* name;
        double StudyRow::*measured;
        const char* fmt;
        const double* paper;
    };
    const Metric metrics[] = {{"scalar ns/ray", &StudyRow::scalar_ns, "%.1f", paper ? paper->scalar_ns : nullptr},
                              {"SIMD ns/ray", &StudyRow::simd_ns, "%.1f", paper ? paper->simd_ns : nullptr},
                              {"SAH", &StudyRow::sah, "%.2f", paper ? paper->sah : nullptr},
                              {"EPO", &StudyRow::epo, "%.2f", paper ? paper->epo : nullptr},
                              {"LCV", &StudyRow::lcv, "%.2f", paper ? paper->lcv : nullptr}};
    std::vector<std::string> header{"metric"};
    for (const PaperBuilder& b : kBuilders) header.push_back(b.label());
    std::vector<std::vector<std::string>> rows;
    for (const Metric& m : metrics) {
        std::vector<std::string> row{m.name};
        for (const PaperBuilder& b : kBuilders) {
            const StudyRow* r = row_of(scene, b.canopy);
            row.push_back(r ? format(m.fmt, r->*m.measured) : "-");
        }
        rows.push_back(row);
        if (!m.paper) continue;
        std::vector<std::string> printed{std::string("paper ") + m.name};
        for (size_t i = 0; i < kBuilderCount; ++i) printed.push_back(format(m.fmt, m.paper[i]));
        rows.push_back(printed);
    }
    return markdown_table(header, rows);
}

std::string correlations(const StudyScene& scene, const PaperScene* paper) {
    std::vector<std::vector<std::string>> rows{
        {"canopy", format("%.3f", correlation(scene.scalar_sah)),
         format("%.3f", correlation(scene.scalar_epo.correlation)) + format(" (a=%.2f)", scene.scalar_epo.alpha),
         format("%.3f", correlation(scene.simd_sah)),
         format("%.3f", correlation(scene.simd_epo.correlation)) + format(" (a=%.2f)", scene.simd_epo.alpha),
         format("%.3f", correlation(scene.simd_lcv.correlation)) + format(" (a=%.2f, ", scene.simd_lcv.alpha) +
             format("b=%.2f)", scene.simd_lcv.beta)}};
    if (paper)
        rows.push_back({"paper", format("%.3f", paper->scalar_sah), format("%.3f", paper->scalar_epo),
                        format("%.3f", paper->simd_sah), format("%.3f", paper->simd_epo), format("%.3f", paper->simd_lcv)});
    return markdown_table({"correlation with ns/ray", "scalar SAH", "scalar SAH+EPO", "SIMD SAH", "SIMD SAH+EPO",
                           "SIMD SAH+EPO+LCV"}, rows);
}

// The correlations of Table 2 over the measured scenes, in kTable2's order.
std::vector<std::vector<double>> table2_values(const StudyResult& study) {
    std::vector<std::vector<double>> values(std::size(kTable2));
    for (const StudyScene& scene : study.scenes) {
        const double v[] = {correlation(scene.scalar_sah), correlation(scene.scalar_epo.correlation), correlation(scene.simd_sah),
                            correlation(scene.simd_epo.correlation), correlation(scene.simd_lcv.correlation)};
        for (size_t k = 0; k < std::size(kTable2); ++k)
            if (!std::isnan(v[k])) values[k].push_back(v[k]);
    }
    return values;
}

double average(const std::vector<double>& v) {
    if (v.empty()) return kNotMeasured;
    double sum = 0;
    for (double x : v) sum += x;
    return sum / double(v.size());
}

double minimum(const std::vector<double>& v) { return v.empty() ? kNotMeasured : *std::min_element(v.begin(), v.end()); }
double maximum(const std::vector<double>& v) { return v.empty() ? kNotMeasured : *std::max_element(v.begin(), v.end()); }

std::string table2(const StudyResult& study) {
    const std::vector<std::vector<double>> values = table2_values(study);
    std::vector<std::vector<std::string>> rows;
    for (size_t k = 0; k < std::size(kTable2); ++k)
        rows.push_back({kTable2[k].what, format("%.3f", average(values[k])), format("%.3f", kTable2[k].average),
                        format("%.3f", minimum(values[k])), format("%.3f", kTable2[k].minimum)});
    return markdown_table({"correlation", "canopy average", "paper", "canopy minimum", "paper"}, rows);
}

std::string fixed_fit(const StudyResult& study) {
    const StudyFit &scalar = study.fixed_scalar, &simd = study.fixed_simd;
    return markdown_table({"fixed parameters for all scenes", "canopy", "paper"},
                          {{"scalar, eq. 6", format("%.3f", correlation(scalar.correlation)) + format(" (a=%.2f)", scalar.alpha),
                            "0.980 (a=0.71)"},
                           {"SIMD, eq. 7", format("%.3f", correlation(simd.correlation)) + format(" (a=%.2f, ", simd.alpha) +
                                               format("b=%.2f)", simd.beta), "0.981 (a=0.14, b=0.76)"}});
}

double change(double after, double before) { return 100.0 * (after / before - 1.0); }

// Per builder, over the scenes: a quantity's average change.
struct Changes {
    std::map<std::string, std::vector<double>> time, sah, epo, permuted;
};

Changes changes_of(const StudyResult& study) {
    Changes c;
    for (const StudyScene& scene : study.scenes)
        for (const PaperBuilder& b : kBuilders) {
            const StudyRow* r = row_of(scene, b.canopy);
            if (!r) continue;
            if (!std::isnan(r->rotated_ns)) {
                c.time[b.canopy].push_back(change(r->rotated_ns, r->simd_ns));
                c.sah[b.canopy].push_back(change(r->rotated_sah, r->sah));
                c.epo[b.canopy].push_back(change(r->rotated_epo, r->epo));
            }
            if (!std::isnan(r->permuted_ns)) c.permuted[b.canopy].push_back(change(r->permuted_ns, r->unpermuted_ns));
        }
    return c;
}

// The paper's sec. 4.4 figures per builder: SIMD time (+90% SBVH and STreelet, +250% Agglo, ~+180% the rest), SAH
// (under +10% SBVH and STreelet, about +50% the others); EPO +290% on average.
std::string paper_rotation(const std::string& builder, bool time) {
    const bool splitting = builder == "sbvh" || builder == "streelet";
    if (time) return splitting ? "+90%" : builder == "agglo" ? "+250%" : "~+180%";
    return splitting ? "under +10%" : "~+50%";
}

std::string percent(double v) { return format("%+.1f%%", v); }

std::string rotation_table(const Changes& c) {
    std::vector<std::vector<std::string>> rows;
    std::vector<double> all_time, all_sah, all_epo;
    for (const PaperBuilder& b : kBuilders) {
        if (!c.time.count(b.canopy)) continue;
        const double t = average(c.time.at(b.canopy)), s = average(c.sah.at(b.canopy)), e = average(c.epo.at(b.canopy));
        all_time.push_back(t), all_sah.push_back(s), all_epo.push_back(e);
        rows.push_back({b.label(), percent(t), paper_rotation(b.canopy, true), percent(s),
                        paper_rotation(b.canopy, false), percent(e)});
    }
    rows.push_back({"average", percent(average(all_time)), "+168%", percent(average(all_sah)), "-", percent(average(all_epo)) + " (paper +290%)"});
    return markdown_table({"builder", "SIMD time", "paper", "SAH", "paper", "EPO"}, rows);
}

std::string permutation_table(const Changes& c) {
    std::vector<std::vector<std::string>> rows;
    std::vector<double> all;
    for (const PaperBuilder& b : kBuilders) {
        if (!c.permuted.count(b.canopy)) continue;
        const std::vector<double>& v = c.permuted.at(b.canopy);
        all.insert(all.end(), v.begin(), v.end());
        rows.push_back({b.label(), percent(average(v)), percent(minimum(v)), percent(maximum(v))});
    }
    rows.push_back({"all", percent(average(all)), percent(minimum(all)), percent(maximum(all))});
    return markdown_table({"builder", "average change", "smallest", "largest"}, rows) +
           "\nPaper (GPU): under 1% change.\n";
}

// The average over scenes of SIMD time's correlation with SAH, over every builder but `without`.
double simd_sah_correlation_without(const StudyResult& study, const std::string& without) {
    std::vector<double> per_scene;
    for (const StudyScene& scene : study.scenes) {
        std::vector<double> sah, ns;
        for (const StudyRow& r : scene.rows)
            if (r.builder != without) sah.push_back(r.sah), ns.push_back(r.simd_ns);
        if (const std::optional<double> c = pearson(sah, ns)) per_scene.push_back(*c);
    }
    return average(per_scene);
}

// A builder's value over the mean of the nine builders'.
double relative_to_mean(const double (&values)[kBuilderCount], size_t builder) {
    double sum = 0;
    for (double v : values) sum += v;
    return values[builder] / (sum / double(kBuilderCount));
}

// Why SAH alone predicts the SIMD times less well than in the paper: the builder whose absence raises the average
// correlation most, where its SAH, time and EPO stand among the builders' here and in the paper, and how far apart
// the builders' times lie.
std::string why_simd_sah_correlates_less(const StudyResult& study) {
    size_t outlier = 0;
    double without_outlier = -2.0, without_others = -2.0;
    for (size_t b = 0; b < kBuilderCount; ++b) {
        const double c = simd_sah_correlation_without(study, kBuilders[b].canopy);
        if (c > without_outlier) std::swap(without_outlier, without_others), without_outlier = c, outlier = b;
        else without_others = std::max(without_others, c);
    }
    std::vector<double> sah_share, time_share;
    std::string spreads;
    int highest_epo = 0, scenes = 0;
    for (const StudyScene& scene : study.scenes) {
        const StudyRow* r = row_of(scene, kBuilders[outlier].canopy);
        if (!r || scene.rows.empty()) continue;
        double sah = 0, ns = 0, slowest = 0, fastest = std::numeric_limits<double>::infinity(), most_epo = 0;
        for (const StudyRow& row : scene.rows) {
            sah += row.sah / double(scene.rows.size()), ns += row.simd_ns / double(scene.rows.size());
            slowest = std::max(slowest, row.simd_ns), fastest = std::min(fastest, row.simd_ns), most_epo = std::max(most_epo, row.epo);
        }
        sah_share.push_back(r->sah / sah), time_share.push_back(r->simd_ns / ns);
        highest_epo += r->epo >= most_epo, ++scenes;
        spreads += (spreads.empty() ? "" : ", ") + scene.scene + format(" %.2fx", slowest / fastest);
    }
    if (scenes == 0) return "";
    std::string paper;
    for (const PaperScene* p : {&kConference, &kDragon}) {
        double slowest = 0, fastest = std::numeric_limits<double>::infinity();
        for (double ns : p->simd_ns) slowest = std::max(slowest, ns), fastest = std::min(fastest, ns);
        paper += (paper.empty() ? "" : "; ") + std::string(p->name) + format(": SAH %.2fx", relative_to_mean(p->sah, outlier)) +
                 format(", time %.2fx the mean", relative_to_mean(p->simd_ns, outlier)) +
                 format(", slowest over fastest %.2fx", slowest / fastest);
    }
    const bool slower = average(sah_share) < average(time_share), overlaps = slower && 2 * highest_epo >= scenes;
    std::string text = "\n\n**Why SAH alone predicts the SIMD times less well here.** Leaving one builder out of every "
                       "scene's correlation, the average SIMD SAH correlation rises most without " + kBuilders[outlier].label() +
                       format(" (from %.3f ", simd_sah_correlation_without(study, "")) + format("to %.3f; ", without_outlier) +
                       format("without any other builder at most %.3f). ", without_others) + "Its tree has on average " +
                       format("%.2fx the builders' mean SAH and ", average(sah_share)) +
                       format("%.2fx their mean SIMD time: it traces ", average(time_share)) +
                       (slower ? "slower" : "faster") + " than its SAH says";
    if (overlaps)
        text += ", and it has the highest EPO of the nine on " + std::to_string(highest_epo) + " of " + std::to_string(scenes) +
                " scenes: its boxes overlap more than their area says, which EPO counts and SAH does not, so adding EPO "
                "gains more here than in the paper";
    return text + ". The paper's " + kBuilders[outlier].paper + ", for comparison: " + paper + ". The builders' SIMD "
           "times, slowest over fastest, here: " + spreads + "; where they lie close together, a few percent of timing "
           "noise, or of cache behaviour that no metric models, weighs more in each correlation.";
}

std::string findings(const StudyResult& study, const Changes& c) {
    const std::vector<std::vector<double>> values = table2_values(study);
    std::string text;
    const auto compare = [&](size_t k) {
        const double ours = average(values[k]);
        return std::string(kTable2[k].what) + " " + format("%.3f", ours) + " against the paper's " +
               format("%.3f", kTable2[k].average) + (ours >= kTable2[k].average - 0.02 ? " (holds)" : " (lower here)");
    };
    text += "Average correlations with measured time: " + compare(0) + "; " + compare(1) + "; " + compare(2) + "; " +
            compare(3) + "; " + compare(4) + ". ";
    const double sah_gain_scalar = average(values[1]) - average(values[0]), sah_gain_simd = average(values[3]) - average(values[2]);
    text += "Adding EPO to SAH " + std::string(sah_gain_scalar > 0.005 ? "improves" : "does not improve") +
            " the scalar prediction here (" + format("%+.3f", sah_gain_scalar) + "; paper +0.079) and " +
            (sah_gain_simd > 0.005 ? "improves" : "does not improve") + " the SIMD one (" + format("%+.3f", sah_gain_simd) +
            "; paper +0.046). ";
    std::vector<double> time, permuted;
    for (const auto& [builder, v] : c.time) time.insert(time.end(), v.begin(), v.end());
    for (const auto& [builder, v] : c.permuted) permuted.insert(permuted.end(), v.begin(), v.end());
    if (!time.empty())
        text += "Rotating scene and rays 45 degrees costs " + percent(average(time)) + " SIMD time on average (paper +168%). ";
    if (!permuted.empty())
        text += "Permuting nodes in memory changes SIMD time by " + percent(average(permuted)) + " on average, " +
                (std::abs(average(permuted)) < 1.0 ? "within" : "beyond") + " the paper's 1% (a CPU's caches see the "
                "layout; one permutation per tree, timed alternately with the original).";
    return text + why_simd_sah_correlates_less(study) + "\n";
}

PaperDocument document(const std::vector<Subject<PaperScene>>& list, const StudyResult& study) {
    PaperDocument d{"Aila, Karras and Laine 2013: quality metrics of BVHs, measured on a CPU",
                    "This is a **quick** run: small scenes, small images, one timing per tree.",
                    "The paper measured 22 scenes on an NVIDIA GTX680 (its \"scalar\" is one lane of 32, its \"SIMD\" the "
                    "32-wide warp). Here \"scalar\" is canopy's bvh2 kernel and \"SIMD\" its widest kernel on the same tree, "
                    "collapsed; both trace the diffuse rays of one frame (`canopy study`, 8 bounces) one at a time on one thread. "
                    "SAH, EPO and LCV are those of the binary tree (the paper's). BBVH is canopy's full sweep SAH builder. The "
                    "paper's rows are quoted beside canopy's for the scenes both have: CONFERENCE, and DRAGON (canopy's is "
                    "decimated).",
                    {}, study_json(study)};
    std::string per_scene;
    for (size_t i = 0; i < list.size(); ++i) {
        const StudyScene& scene = study.scenes.at(i);
        per_scene += "### " + scene.scene + (list[i].paper ? " (paper: " + std::string(list[i].paper->name) + ")" : "") + "\n\n";
        per_scene += table1(scene, list[i].paper) + "\n" + correlations(scene, list[i].paper) + "\n";
    }
    const Changes c = changes_of(study);
    d.sections = {
        {"Table 1: per scene", per_scene},
        {"Table 2: correlations over the scenes", table2(study) + "\n"},
        {"Sec. 4.3: one alpha and beta for every scene", fixed_fit(study) + "\n"},
        {"Sec. 4.4: scene and rays rotated 45 degrees about (1, 1, 1)",
         "Change against the unrotated tree, averaged over the scenes.\n\n" + rotation_table(c) + "\n"},
        {"Sec. 6: nodes permuted in memory",
         "SIMD time of each tree with its wide nodes shuffled (fixed seed), against the same tree in the builder's "
         "order, timed alternately.\n\n" + permutation_table(c) + "\n"},
        {"What holds, what does not", findings(study, c)},
    };
    return d;
}

}  // namespace

std::optional<PaperDocument> reproduce_aila_karras_laine_2013(const ReproduceOptions& o) {
    const std::vector<Subject<PaperScene>> list = subjects<PaperScene>(o, kSubjects);
    StudyOptions s;
    for (const Subject<PaperScene>& subject : list) s.scenes.push_back(subject.spec);
    for (const PaperBuilder& b : kBuilders) s.builders.push_back(b.canopy);
    s.rotate = s.permute_nodes = true;
    if (o.quick) s.width = 64, s.height = 48, s.repeats = 1;
    progress_section("aila-karras-laine-2013", "Tables 1 and 2, rotation and permutation");
    const StudyResult study = measure_study(s);
    if (!distributed::is_root()) return std::nullopt;
    return document(list, study);
}

}  // namespace canopy
