#pragma once
// `--builder auto`: "model only what a scene requires", measured rather than assumed. Cheap statistics (one pass
// over the triangles) give each candidate a prior prediction of its time to image (build + frames x frame time);
// then auto builds candidates on the machine at hand and traces a small sample of the planned frame's pixels
// through each, re-predicting the untried ones from what it measured, while the calibration's waste stays within a
// share of the best time to image found. The winner's tree is the one built during the calibration.
#include "scenes/scene.h"

#include <string>
#include <vector>

namespace canopy {

class Accelerator;

// What auto times its candidates with: a sample of the caller's own workload (the renderer's: the planned frame's
// paths; the library's: random rays through the scene), traced through each candidate's tree.
class WorkloadSample {
public:
    virtual ~WorkloadSample() = default;
    // The whole workload, in the pixels of a frame that prior_estimates predicts for, and the image's aspect.
    virtual uint64_t pixels() const = 0;
    virtual double aspect() const = 0;
    // Traces one part in `stride` of the workload (1: all of it) through `tree`.
    virtual void trace(const Accelerator& tree, uint32_t stride) = 0;
    // The share of the whole workload that one part in `stride` is.
    virtual double share(uint32_t stride) const = 0;
};

struct SceneStatistics {
    uint64_t triangles = 0;         // as traced (every instance's copy)
    uint64_t unique_triangles = 0;  // as stored in meshes: what a two-level build builds
    uint64_t placements = 0;        // (instance, non-empty object) pairs: the two-level top level's size
    // Sum of triangle-box half areas over the sum of twice the triangle areas: 1 for axis-aligned right triangles,
    // large for long diagonal slivers, whose boxes spatial splits shrink (the split papers' motivation).
    double box_excess = 1.0;
    // (Sum of triangle-box half areas - sum of twice the triangle areas) over the half area of the meshes' bounds:
    // by Crofton's formula, how many more triangle boxes than triangles a random ray through the scene pierces, an
    // upper bound on the tests per ray that splitting triangles can save.
    double reducible_cover = 0.0;
    // Sum of A_ideal over the sum of triangle-box areas: the fill below which early split clipping's automatic
    // SA_max splits (accel/builders/early_split_clipping.h); from it up, `esc` builds binned's tree.
    double box_fill = 1.0;
    // The camera's eye inside the scene's bounds: a room seen from within, where paths bounce to the bounce limit
    // and so traces several times an outside view's rays a pixel (docs/results.md#autos-priors-and-samples).
    bool camera_inside = false;
    // The areas of the triangles in the camera's view projected on its image plane, over the image's area: the
    // share of the frame the scene covers times its depth complexity, below one for a scan seen from outside and
    // several for a room seen from inside (docs/results.md#autos-priors-and-samples).
    double projected_area = 1.0;
};

// Flattening copies every instance: past this many triangles (about 2 GB of flat layout) two-level only.
constexpr uint64_t kMaxFlattenedTriangles = 16'000'000;
// Whether auto's candidates include flat trees for a scene of `triangles` flattened, `unique_triangles` in meshes.
bool flat_candidates(uint64_t triangles, uint64_t unique_triangles);

// `image_aspect`, width over height, frames the camera's view for projected_area.
SceneStatistics scene_statistics(const Scene& scene, const FlatScene& flat, double image_aspect);

// One sample of the planned frame through a candidate's tree.
struct SampleReading {
    double cost_ms = 0.0;   // all it took, warm-up and retraced samples included: auto's time to image pays it
    double timed_ms = 0.0;  // the timed trace the frame is read from: the longer, the less noise in that reading
    double frame_ms = 0.0;  // the whole frame's time, read from the timed trace
};

// A reading of a candidate's binary tree.
struct TreeReading {
    double sibling_overlap = -1.0;  // accel/metrics.h; negative where the build kept no binary tree
    double cost_ms = 0.0;           // what reading it took: auto's time to image pays it
};

// What auto measures on the machine at hand. The accelerator builds real trees and traces real sample pixels;
// tests answer with fixed costs, so that decisions are pinned through predicted and "measured" costs, not timings.
class Calibration {
public:
    virtual ~Calibration() = default;
    // Builds the candidate (keeping it until the next build of another); returns the build's milliseconds.
    virtual double build(const std::string& builder, const std::string& toplevel) = 0;
    // Traces the sample pixels of the planned frame through the last build.
    virtual SampleReading sample_frame() = 0;
    // Reads the last build's binary tree.
    virtual TreeReading read_tree() = 0;
    // The candidate's tree is no longer wanted (it lost to another): its memory may go.
    virtual void discard(const std::string& builder, const std::string& toplevel) = 0;
    // What a sample through a tree of this frame time is expected to cost, retraces for a longer timed sample included.
    virtual double sample_cost_ms(double frame_ms) const = 0;
};

struct CandidateEstimate {
    std::string builder, toplevel;
    double build_ms = 0.0, frame_ms = 0.0;  // measured when `measured`, predicted otherwise
    double sample_ms = 0.0;                 // the sample's cost, when measured
    double sampled_frame_ms = 0.0;          // the sample's own reading of the frame, when measured
    double sample_weight = 0.0;             // that reading's weight in frame_ms against the rescaled prior's
    bool measured = false;
    std::string note;  // why it was or was not tried
    double time_to_image_ms(int frames) const { return build_ms + double(frames) * frame_ms; }
};

struct AutoChoice {
    std::string builder;            // a registered builder
    std::string toplevel = "flat";  // flat, or rebraid for instanced scenes
    std::string reason;             // one line: the statistics, the calibration and the winner's times
    std::vector<CandidateEstimate> candidates;  // in the order auto tried or ruled them out
    double calibration_ms = 0.0;    // builds of the losers and every sample: what measuring cost on top of the winner
    double budget_ms = 0.0;         // what the calibration may waste: kCalibrationBudget of the winner's time to image
    double time_to_image_ms = 0.0;  // predicted for auto itself: every build and sample, and the winner's frames
    double sibling_overlap = -1.0;  // of binned's tree, where binned was measured and sbvh judged by it; else negative
};

// The candidates, build and frame costs predicted from the statistics alone (the order the calibration tries
// them in) for `frames` frames of `pixels` pixels. Public for tests and --explain.
std::vector<CandidateEstimate> prior_estimates(const SceneStatistics& stats, int frames, uint64_t pixels);

// The calibration may waste (build losers, trace samples) this share of the best time to image it has measured.
constexpr double kCalibrationBudget = 0.05;

// A measured candidate's frame time: its sample's reading and its prior rescaled by every measured candidate, each
// weighted by the inverse of its variance in log terms. The prior's relative frame times are within about 10% on the
// scenes they were fitted on, so kPriorLogVariance is 0.1 squared; a sample's reading's is kSampleLogVariance over
// its timed milliseconds, as the shortest samples misread a frame by far more than samples of a few milliseconds
// (docs/results.md#autos-priors-and-samples).
constexpr double kPriorLogVariance = 0.01;
constexpr double kSampleLogVariance = 0.003;
double sample_weight(double timed_ms);

// A sample of `sample_ms` through one tile in `stride` was too short to time (under `min_ms`): the stride of the
// next, sized by this one's rate to take kSampleAim times min_ms, at most half of `stride` and at least 1 (the whole
// frame). Growing by a fixed factor instead overshot (docs/results.md#autos-priors-and-samples).
constexpr double kSampleAim = 1.25;
uint32_t next_sample_stride(uint32_t stride, double sample_ms, double min_ms);
// Before its sample, a tree after the calibration's first traces one tile in this many, untimed for the reading: a
// sample of a tree just built pays the misses that bring its nodes into the caches, which a whole frame amortises.
// Unwarmed, a one-frame sample could rank a faster tree behind a slower one
// (docs/results.md#autos-priors-and-samples). The first tree's warm-up is half its sample, which also wakes the
// threads.
constexpr uint32_t kTreeWarmUpStride = 256;
// What such a sample costs through a tree of `frame_ms` (not the first): its warm-up, one tile in `stride`, and where
// that is under `min_ms`, the retrace next_sample_stride sizes (kSampleAim times min_ms, twice the first at least,
// the whole frame at most), since counting the first trace alone undercounted retraced samples several times over
// (docs/results.md#autos-priors-and-samples).
double expected_sample_cost_ms(double frame_ms, uint32_t stride, double min_ms);

// sbvh's frame relative to binned's on a scene without slivers whose binned tree has this sibling overlap.
double sbvh_frame_from_overlap(double overlap);

// Chooses a candidate for `frames` frames of `pixels` pixels. Measures first the candidate predicted best, or, where
// it costs more to build than it is predicted to save over the cheapest build predicted near it, that one; then, in
// the order of what each would cost from here (build + frames), every candidate predicted to save more than its build
// against the best measured frames, and every other whose build and sample fit the budget; predicts the untried ones
// by scaling their priors by what the measured ones took against theirs, and the measured ones' frames by their
// samples' readings weighed against those rescaled priors (sample_weight). Once binned's tree is measured, sbvh's
// frame is predicted from that tree's sibling overlap (sbvh_frame_from_overlap) instead of the scene's class. A
// measured tree's build is spent, so the measured candidate of the least frame time wins.
AutoChoice choose_builder(const SceneStatistics& stats, int frames, uint64_t pixels, Calibration& calibration);

// --explain: one line per candidate (predicted or measured build and frame, time to image, note), then the winner.
std::string explain(const AutoChoice& choice, int frames);

}  // namespace canopy
