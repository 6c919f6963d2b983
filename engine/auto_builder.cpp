#include "engine/auto_builder.h"

#include "accel/builder.h"
#include "accel/builders/early_split_clipping.h"
#include "accel/parallel.h"

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <stdexcept>

namespace canopy {

namespace {

// The sums over triangles the statistics are ratios of.
struct Sums {
    double box_half_areas = 0.0, twice_areas = 0.0, ideal_areas = 0.0;
    void add(const Triangle& t) {
        box_half_areas += BBox::of(t).half_area();
        twice_areas += 2.0 * triangle_area(t);
        ideal_areas += ideal_area(t);
    }
    Sums& operator+=(const Sums& o) {
        box_half_areas += o.box_half_areas, twice_areas += o.twice_areas, ideal_areas += o.ideal_areas;
        return *this;
    }
};

// At most this many triangles are projected: a larger (flattened, instanced) scene is sampled at an even stride.
constexpr size_t kProjectedSample = 1u << 20;

// A triangle of area A and normal n whose centroid lies at d from the eye, depth z = d.forward, covers A |n.d| / z^3
// of the image plane at unit distance (its solid angle A |n.d| / |d|^3 over the plane's cos^3 at that direction);
// only the triangles whose centroid the view contains count. Over the plane's area 4 tan^2(fov / 2) x aspect. In
// doubles: A |n.d| / z^3 goes as the coordinates' cube, beyond float range at 1e13, or below it at 1e-13.
double projected_area(std::span<const Triangle> triangles, const Camera& camera, double aspect) {
    using D = glm::dvec3;
    const D eye(camera.eye), forward = glm::normalize(D(camera.target) - eye);
    const D right = glm::normalize(glm::cross(forward, D(camera.up))), up = glm::cross(right, forward);
    const double tan_half_fov = std::tan(0.5 * double(camera.fov_deg) * std::numbers::pi / 180.0);
    const size_t stride = std::max<size_t>(1, triangles.size() / kProjectedSample);
    const double sum = parallel::reduce(
        triangles.size() / stride, 16 * 1024, 0.0,
        [&](size_t begin, size_t end) {
            double partial = 0.0;
            for (size_t i = begin; i < end; ++i) {
                const Triangle& t = triangles[i * stride];
                const D v0(t.v0), v1(t.v1), v2(t.v2);
                const D d = (v0 + v1 + v2) / 3.0 - eye;
                const double z = glm::dot(d, forward);
                if (!(z > 0.0) || std::fabs(glm::dot(d, right)) > z * tan_half_fov * aspect ||
                    std::fabs(glm::dot(d, up)) > z * tan_half_fov)
                    continue;
                const D half_normal = 0.5 * glm::cross(v1 - v0, v2 - v0);
                partial += std::fabs(glm::dot(half_normal, d)) / (z * z * z);
            }
            return partial;
        },
        [](double a, double b) { return a + b; });
    return sum * double(stride) / (4.0 * tan_half_fov * tan_half_fov * aspect);
}

}  // namespace

// Box excess over each mesh's own triangles, not the flattened copies: an instanced scene pays for its unique
// geometry only (zoo-1024's 50 M instanced triangles are 148 k unique ones).
SceneStatistics scene_statistics(const Scene& scene, const FlatScene& flat, double image_aspect) {
    SceneStatistics s;
    s.triangles = flat.triangles.size();
    for (const Instance& instance : scene.instances)
        for (const Object& object : scene.meshes[instance.mesh].objects) s.placements += object.triangle_count > 0;
    Sums sums;
    BBox bounds;  // of the meshes, each in its own space: the world for a scene of identity placements
    for (const Mesh& mesh : scene.meshes) {
        for (const Vec3& p : mesh.positions) bounds.extend(p);
        s.unique_triangles += mesh.triangles.size();
        sums += parallel::reduce(
            mesh.triangles.size(), 16 * 1024, Sums{},
            [&](size_t begin, size_t end) {
                Sums partial;
                for (size_t i = begin; i < end; ++i) {
                    const glm::uvec3& f = mesh.triangles[i];
                    partial.add({mesh.positions[f.x], mesh.positions[f.y], mesh.positions[f.z]});
                }
                return partial;
            },
            [](Sums a, const Sums& b) { return a += b; });
    }
    s.box_excess = sums.twice_areas > 0.0 ? sums.box_half_areas / sums.twice_areas : 1.0;
    s.box_fill = sums.box_half_areas > 0.0 ? sums.ideal_areas / (2.0 * sums.box_half_areas) : 1.0;
    const double area = bounds.empty() ? 0.0 : double(bounds.half_area());
    s.reducible_cover = area > 0.0 ? std::max(0.0, sums.box_half_areas - sums.twice_areas) / area : 0.0;
    const Camera camera = scene_camera(scene, flat);
    s.camera_inside = glm::all(glm::greaterThan(camera.eye, flat.bounds.lower)) && glm::all(glm::lessThan(camera.eye, flat.bounds.upper));
    s.projected_area = projected_area(flat.triangles, camera, image_aspect);
    return s;
}

namespace {

// A candidate: a builder under a top level, with its prior (accel/builder.h's AutoPrior). The flat candidates are
// the registered builders with a prior, which say where they were fitted.
struct Candidate {
    std::string builder;
    std::string toplevel;
    AutoPrior prior;
};

// Scenes whose triangle boxes are this much larger than the triangles are made of long diagonal slivers, the only
// scenes where spatial splits pay; the threshold lies well between the sliver fields' excess and every other scene's
// (docs/results.md#autos-priors-and-samples).
constexpr double kSliverExcess = 5.0;
bool slivers(const SceneStatistics& s) { return s.box_excess > kSliverExcess; }
// Scanned and finely tessellated surfaces have randomly oriented triangles of similar size, whose boxes exceed them
// more than architecture's, large axis-aligned walls next to small detail; the threshold separates the measured
// scenes of both (docs/results.md#autos-priors-and-samples).
constexpr double kScanExcess = 1.75;
bool architecture(const SceneStatistics& s) { return s.box_excess < kScanExcess; }
// Architecture whose triangle boxes a ray pierces far more often than their triangles (crytek-sponza's big
// overlapping wall and arch triangles, alone of the measured scenes): splitting pays there even without slivers.
constexpr double kSplitCover = 5.0;
bool dense_boxes(const SceneStatistics& s) { return architecture(s) && s.reducible_cover > kSplitCover; }
// Objects placed more than once: flattening copies them.
bool instanced(const SceneStatistics& s) { return s.triangles > s.unique_triangles; }

// Sliver fields whose slivers cross the scene, against clustered ones: the reducible cover grows with the triangle
// count n about as n^0.6 in both generators, and this boundary lies between gen:cylinders' long diagonals and
// gen:foliage's clustered leaves at every count measured (docs/results.md#autos-priors-and-samples). Splitting every
// sliver's box at once (esc) pays most where slivers cross; splitting only where nodes overlap (sbvh, bonsai-split)
// matches it where they cluster.
constexpr double kCrossingCover = 0.35, kCrossingCoverExponent = 0.6;
bool crossing_slivers(const SceneStatistics& s) {
    return slivers(s) && s.reducible_cover > kCrossingCover * std::pow(double(s.unique_triangles), kCrossingCoverExponent);
}

// A prior's frame relative to binned's on a scene of this class.
double relative_frame(const AutoPrior& p, const SceneStatistics& s) {
    if (p.instanced > 0.0 && instanced(s)) return p.instanced;
    if (crossing_slivers(s)) return p.crossing_slivers;
    if (slivers(s)) return p.clustered_slivers;
    return dense_boxes(s) ? p.dense_boxes : architecture(s) ? p.architecture : p.other;
}
// Where binned's tree is measured, its sibling overlap o (accel/metrics.h) predicts sbvh's gain better than the class:
// what object splits could not separate is what spatial splits may. A least-squares line over the scenes above the
// onset, which also predicted the held-out models better than the class prior
// (docs/results.md#autos-priors-and-samples); floored at crytek-sponza's gain, the largest fitted; sliver fields keep
// their class priors, as theirs lie off the line.
constexpr double kSbvhOverlapOnset = 0.17, kSbvhOverlapGain = 3.8, kSbvhFrameFloor = 0.83;
// rebraid's traversal against flat's, as measured on zoo-64 (docs/results.md#autos-priors-and-samples). Plain
// two-level builds in the same time and traces slower, so it is no candidate. Instanced objects: each unique triangle
// is built once, at a cost per unique triangle measured on zoo-64; a higher prior had scaled every flat build down once
// rebraid was measured.
constexpr AutoPrior kRebraidPrior{160.0, 160.0, 1.3, 1.3, 1.3, 1.3, 1.3};

// The registered builders with a prior, flat, then binned under a re-braided top level.
std::vector<Candidate> candidates() {
    std::vector<Candidate> out;
    for (const BuilderEntry& entry : builders())
        if (entry.auto_prior) out.push_back({entry.name, "flat", *entry.auto_prior});
    out.push_back({"binned", "rebraid", kRebraidPrior});
    return out;
}

// Frame time per pixel with binned, 2 threads, bvh8, by class: rooms seen from inside, slivers crossing the scene and
// clustered ones (giving clustered slivers the crossing ones' cost made auto build sbvh first for a one-frame foliage
// image). Objects seen from outside cost by what of the frame they cover: a pixel that misses all, plus a least-squares
// fit (in logs) per unit of projected area, capped at the largest fitted area; one constant for all had priced an
// object covering little of the frame far too dear, and auto built binned where lbvh's cheaper build was the better
// choice for one frame (docs/results.md#autos-priors-and-samples). The calibration replaces these by what it measures.
constexpr double kInsideNsPerPixel = 2000.0;
constexpr double kMissNsPerPixel = 14.0, kProjectedAreaNsPerPixel = 118.0, kMaxFittedProjectedArea = 2.1;
constexpr double kCrossingSliverNsPerPixel = 3000.0, kClusteredSliverNsPerPixel = 470.0;
double frame_ns_per_pixel(const SceneStatistics& s) {
    if (slivers(s)) return crossing_slivers(s) ? kCrossingSliverNsPerPixel : kClusteredSliverNsPerPixel;
    if (s.camera_inside) return kInsideNsPerPixel;
    return kMissNsPerPixel + kProjectedAreaNsPerPixel * std::min(s.projected_area, kMaxFittedProjectedArea);
}
// A frame of `pixels` through a tree that traces in `relative` times binned's frame.
double prior_frame_ms(const SceneStatistics& s, uint64_t pixels, double relative) {
    return double(pixels) * frame_ns_per_pixel(s) * 1e-6 * relative;
}
bool allowed(const Candidate& c, const SceneStatistics& stats) {
    // A prior may stop at a box fill: from it up, esc's automatic SA_max splits nothing and esc builds binned's tree.
    if (stats.box_fill >= c.prior.max_box_fill) return false;
    const bool two_level = c.toplevel != "flat";
    if (two_level) return instanced(stats);  // two-level only with instances
    return flat_candidates(stats.triangles, stats.unique_triangles);
}

double geometric_mean(const std::vector<double>& ratios) {
    double log_sum = 0.0;
    for (double r : ratios) log_sum += std::log(r);
    return std::exp(log_sum / double(ratios.size()));
}

// The measured candidates' costs against their priors, as factors for the others': how much faster or slower
// this machine and scene are than the priors assumed. Frames by the samples' own readings.
std::pair<double, double> measured_scales(const std::vector<CandidateEstimate>& now, const std::vector<CandidateEstimate>& prior) {
    std::vector<double> build, frame;
    for (size_t i = 0; i < now.size(); ++i) {
        if (!now[i].measured) continue;
        if (now[i].build_ms > 0.0 && prior[i].build_ms > 0.0) build.push_back(now[i].build_ms / prior[i].build_ms);
        if (now[i].sampled_frame_ms > 0.0 && prior[i].frame_ms > 0.0) frame.push_back(now[i].sampled_frame_ms / prior[i].frame_ms);
    }
    return {build.empty() ? 1.0 : geometric_mean(build), frame.empty() ? 1.0 : geometric_mean(frame)};
}

// A measured candidate's frame: its reading and its rescaled prior, geometrically weighted (sample_weight).
double blended_frame(const CandidateEstimate& measured, double rescaled_prior_ms) {
    if (measured.sampled_frame_ms <= 0.0 || rescaled_prior_ms <= 0.0) return measured.sampled_frame_ms;
    const double w = measured.sample_weight;
    return std::exp(w * std::log(measured.sampled_frame_ms) + (1.0 - w) * std::log(rescaled_prior_ms));
}

// sbvh's prior frame, where auto has not yet decided on sbvh, from the sibling overlap of binned's tree.
void predict_sbvh_from_overlap(double overlap, const SceneStatistics& stats, uint64_t pixels,
                               std::vector<CandidateEstimate>& prior, const std::vector<bool>& decided) {
    for (size_t i = 0; i < prior.size(); ++i)
        if (!decided[i] && prior[i].builder == "sbvh" && prior[i].toplevel == "flat")
            prior[i].frame_ms = prior_frame_ms(stats, pixels, sbvh_frame_from_overlap(overlap));
}

std::string label(const CandidateEstimate& c) { return c.toplevel == "flat" ? c.builder : c.toplevel + "/" + c.builder; }

}  // namespace

double sbvh_frame_from_overlap(double overlap) {
    return std::max(kSbvhFrameFloor, 1.0 - kSbvhOverlapGain * std::max(0.0, overlap - kSbvhOverlapOnset));
}

std::vector<CandidateEstimate> prior_estimates(const SceneStatistics& stats, int frames, uint64_t pixels) {
    std::vector<CandidateEstimate> out;
    for (const Candidate& candidate : candidates()) {
        if (!allowed(candidate, stats)) continue;
        const AutoPrior& p = candidate.prior;
        const bool two_level = candidate.toplevel != "flat";
        const double built = double(two_level ? stats.unique_triangles : stats.triangles);
        CandidateEstimate c{candidate.builder, candidate.toplevel};
        c.build_ms = built * (slivers(stats) ? p.sliver_build_ns_per_triangle : p.build_ns_per_triangle) * 1e-6;
        c.frame_ms = prior_frame_ms(stats, pixels, relative_frame(p, stats));
        out.push_back(c);
    }
    std::stable_sort(out.begin(), out.end(), [&](const CandidateEstimate& a, const CandidateEstimate& b) {
        return a.time_to_image_ms(frames) < b.time_to_image_ms(frames);
    });
    return out;
}

// The first candidate measured: the one predicted best, unless it costs more to build than it is predicted to save
// over the cheapest build predicted within kFirstSpread of it; then that cheapest build, which gives the priors their
// scale before an expensive build is risked on them (a slow optimiser predicted best by a small margin was built and
// then traced no faster than binned). Always starting from the cheapest build near the best had auto measure lbvh
// first at one frame on small scans, where binned is predicted to save several times its extra build, and then keep
// lbvh, as binned's whole build and sample would no longer pay for themselves
// (docs/results.md#autos-priors-and-samples).
constexpr double kFirstSpread = 1.1;
size_t first_candidate(const std::vector<CandidateEstimate>& prior, int frames) {
    const double best = prior.front().time_to_image_ms(frames);  // prior_estimates sorts them
    size_t cheapest = 0;
    for (size_t i = 1; i < prior.size(); ++i)
        if (prior[i].time_to_image_ms(frames) <= kFirstSpread * best && prior[i].build_ms < prior[cheapest].build_ms) cheapest = i;
    const double extra_build = prior.front().build_ms - prior[cheapest].build_ms;
    const double saving = prior[cheapest].time_to_image_ms(frames) - best;
    return extra_build <= saving ? 0 : cheapest;
}

AutoChoice choose_builder(const SceneStatistics& stats, int frames, uint64_t pixels, Calibration& calibration) {
    std::vector<CandidateEstimate> prior = prior_estimates(stats, frames, pixels);
    std::vector<CandidateEstimate> now = prior;
    std::vector<bool> decided(now.size(), false);
    std::vector<size_t> order;  // the candidates as auto decided on them
    AutoChoice choice;
    std::optional<size_t> best;  // the measured candidate of the least frame time: its build is spent already
    double spent = 0.0;          // every build and sample so far
    const auto frames_ms = [&](const CandidateEstimate& c) { return double(frames) * c.frame_ms; };
    for (;;) {
        // What is left to pay after the calibration: an untried candidate's build and frames, the best's frames.
        const auto [build_scale, frame_scale] = measured_scales(now, prior);
        std::optional<size_t> next;
        for (size_t i = 0; i < now.size(); ++i) {
            if (decided[i]) continue;
            now[i].build_ms = prior[i].build_ms * build_scale, now[i].frame_ms = prior[i].frame_ms * frame_scale;
            if (!next || now[i].time_to_image_ms(frames) < now[*next].time_to_image_ms(frames)) next = i;
        }
        if (!best) next = first_candidate(prior, frames);
        if (!next) break;
        CandidateEstimate& c = now[*next];
        decided[*next] = true;
        order.push_back(*next);
        const double left_ms = best ? frames_ms(now[*best]) : 0.0;
        const double budget = kCalibrationBudget * (best ? now[*best].build_ms + left_ms : 0.0);
        const double waste = spent - (best ? now[*best].build_ms : 0.0);
        const double sample = calibration.sample_cost_ms(c.frame_ms);
        if (!best) c.note = *next == 0 ? "predicted best: measured first" : "the cheapest build predicted near the best: measured first";
        else if (c.build_ms + sample + frames_ms(c) < left_ms) c.note = "predicted to save more than its build";
        else if (waste + c.build_ms + sample <= budget) c.note = "within the calibration budget";
        else {
            c.note = "not measured: saves less than its build as predicted, and over the budget";
            continue;
        }
        c.build_ms = calibration.build(c.builder, c.toplevel);
        const SampleReading reading = calibration.sample_frame();
        c.sample_ms = reading.cost_ms, c.sampled_frame_ms = reading.frame_ms, c.sample_weight = sample_weight(reading.timed_ms);
        c.measured = true;
        spent += c.build_ms + c.sample_ms;
        if (c.builder == "binned" && c.toplevel == "flat" && !slivers(stats)) {
            const TreeReading tree = calibration.read_tree();
            spent += tree.cost_ms;
            choice.sibling_overlap = tree.sibling_overlap;
            if (choice.sibling_overlap >= 0.0) predict_sbvh_from_overlap(choice.sibling_overlap, stats, pixels, prior, decided);
        }
        // Every measured frame blended with its prior at the scale every reading now gives; then the newcomer against
        // the best so far.
        const double rescaled = measured_scales(now, prior).second;
        for (size_t i = 0; i < now.size(); ++i)
            if (now[i].measured) now[i].frame_ms = blended_frame(now[i], prior[i].frame_ms * rescaled);
        if (!best || c.frame_ms < now[*best].frame_ms) {
            if (best) calibration.discard(now[*best].builder, now[*best].toplevel);
            best = *next;
        } else {
            calibration.discard(c.builder, c.toplevel);
        }
    }
    if (!best) throw std::logic_error("auto: no candidate for this scene");
    for (const size_t i : order) choice.candidates.push_back(now[i]);
    const CandidateEstimate& winner = now[*best];
    choice.builder = winner.builder, choice.toplevel = winner.toplevel;
    choice.calibration_ms = spent - winner.build_ms;
    choice.budget_ms = kCalibrationBudget * winner.time_to_image_ms(frames);
    choice.time_to_image_ms = spent + frames_ms(winner);
    const size_t measured = size_t(std::count_if(now.begin(), now.end(), [](const CandidateEstimate& c) { return c.measured; }));
    char reason[512];
    std::snprintf(reason, sizeof reason,
                  "%llu triangles (%llu unique) in %llu placed objects, box excess %.2f, fill %.2f, reducible cover %.1f, camera %s, projected area %.2f; "
                  "%zu of %zu candidates measured (calibration %.1f ms); %d frames planned: %s, build %.1f ms + %d x %.1f ms",
                  (unsigned long long)stats.triangles, (unsigned long long)stats.unique_triangles,
                  (unsigned long long)stats.placements, stats.box_excess, stats.box_fill, stats.reducible_cover,
                  stats.camera_inside ? "inside" : "outside", stats.projected_area, measured, now.size(), choice.calibration_ms, frames,
                  label(winner).c_str(), winner.build_ms, frames, winner.frame_ms);
    choice.reason = reason;
    if (choice.sibling_overlap >= 0.0) {
        std::snprintf(reason, sizeof reason, "; binned's sibling overlap %.3f: sbvh's frame predicted %.3fx binned's",
                      choice.sibling_overlap, sbvh_frame_from_overlap(choice.sibling_overlap));
        choice.reason += reason;
    }
    return choice;
}

double sample_weight(double timed_ms) {
    const double sample_variance = kSampleLogVariance / std::max(timed_ms, 1e-3);
    return kPriorLogVariance / (kPriorLogVariance + sample_variance);
}

uint32_t next_sample_stride(uint32_t stride, double sample_ms, double min_ms) {
    const double sized = double(stride) * std::max(sample_ms, 0.0) / (kSampleAim * min_ms);
    return uint32_t(std::clamp(std::floor(sized), 1.0, std::max(1.0, double(stride / 2))));
}

bool flat_candidates(uint64_t triangles, uint64_t unique_triangles) {
    return triangles <= unique_triangles || triangles <= kMaxFlattenedTriangles;
}

double expected_sample_cost_ms(double frame_ms, uint32_t stride, double min_ms) {
    const double warm_up = frame_ms / kTreeWarmUpStride, first = frame_ms / double(std::max(stride, 1u));
    if (first >= min_ms || stride <= 1) return warm_up + first;
    return warm_up + first + std::min(frame_ms, std::max(kSampleAim * min_ms, 2.0 * first));
}

std::string explain(const AutoChoice& choice, int frames) {
    std::string out;
    char line[320];
    std::snprintf(line, sizeof line, "  %-22s %10s %10s %14s  %s\n", "candidate", "build ms", "frame ms",
                  ("TTI@" + std::to_string(frames) + " ms").c_str(), "");
    out += line;
    for (const CandidateEstimate& c : choice.candidates) {
        char measured[96] = "predicted; ";
        if (c.measured)
            std::snprintf(measured, sizeof measured, "measured (sample read %.2f ms, weight %.2f); ", c.sampled_frame_ms, c.sample_weight);
        std::snprintf(line, sizeof line, "  %-22s %10.2f %10.2f %14.1f  %s%s\n", label(c).c_str(), c.build_ms, c.frame_ms,
                      c.time_to_image_ms(frames), measured, c.note.c_str());
        out += line;
    }
    std::snprintf(line, sizeof line,
                  "  chosen: %s%s, the least frame time measured (builds are spent); calibration %.1f ms (builds of the "
                  "others and the samples), budget %.1f ms (%.0f%% of its time to image); time to image with the "
                  "calibration %.1f ms\n",
                  choice.toplevel == "flat" ? "" : (choice.toplevel + "/").c_str(), choice.builder.c_str(),
                  choice.calibration_ms, choice.budget_ms, 100.0 * kCalibrationBudget, choice.time_to_image_ms);
    out += line;
    return out;
}

}  // namespace canopy
