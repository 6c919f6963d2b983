// `--builder auto`: its priors, its calibration's order and budget against fixed costs, its frame samples, and a
// real choice on a generated scene.
#include "oracle.h"
#include "renderer/frames.h"
#include "engine/auto_builder.h"
#include "engine/random_ray_sample.h"
#include "accel/builders/early_split_clipping.h"

#include <algorithm>
#include <map>
#include <set>

using namespace canopy;
using namespace canopy::test;

namespace {

// A machine and scene of known costs: what auto's calibration would measure, per candidate; what it built, traced
// and discarded, in order.
struct FixedCosts final : Calibration {
    struct Costs { double build_ms, frame_ms; };
    std::map<std::string, Costs> costs;  // by builder (flat) or "rebraid/binned"
    std::vector<std::string> built, discarded;
    double share = 0.01;
    std::string last;

    static std::string key(const std::string& builder, const std::string& toplevel) {
        return toplevel == "flat" ? builder : toplevel + "/" + builder;
    }
    double build(const std::string& builder, const std::string& toplevel) override {
        last = key(builder, toplevel);
        built.push_back(last);
        return costs.at(last).build_ms;
    }
    SampleReading sample_frame() override {
        const double frame = costs.at(last).frame_ms;
        return {frame * share, frame * share, frame};
    }
    TreeReading read_tree() override { return {overlap, 0.0}; }
    void discard(const std::string& builder, const std::string& toplevel) override { discarded.push_back(key(builder, toplevel)); }
    double sample_cost_ms(double frame_ms) const override { return frame_ms * share; }
    double overlap = -1.0;  // every tree's sibling overlap; negative: none kept
};

// Costs exactly as the priors predict them for these statistics.
FixedCosts prior_costs(const SceneStatistics& stats, int frames, uint64_t pixels) {
    FixedCosts fixed;
    for (const CandidateEstimate& c : prior_estimates(stats, frames, pixels))
        fixed.costs[FixedCosts::key(c.builder, c.toplevel)] = {c.build_ms, c.frame_ms};
    return fixed;
}

SceneStatistics sponza_statistics() {
    SceneStatistics s;
    s.triangles = s.unique_triangles = 262205;
    s.box_excess = 1.48, s.reducible_cover = 6.8, s.camera_inside = true, s.box_fill = 0.36;
    return s;
}

constexpr uint64_t kPixels = 1024 * 768;

}  // namespace

// What a sample costs auto in all: the measured candidates' samples.
double samples_ms(const AutoChoice& choice) {
    double sum = 0.0;
    for (const CandidateEstimate& c : choice.candidates) sum += c.sample_ms;
    return sum;
}

TEST_CASE("auto measures the predicted best first unless its extra build exceeds what it is predicted to save", "[auto]") {
    // A small scan seen from outside, planned for 16 frames: binned is predicted best, lbvh's frames 12% slower for a
    // build cheaper by far less than that; binned is measured first, and it wins.
    SceneStatistics scan;
    scan.triangles = scan.unique_triangles = 34594, scan.box_excess = 1.9, scan.reducible_cover = 2.0, scan.box_fill = 0.3;
    scan.projected_area = 0.36;
    const std::vector<CandidateEstimate> scan_prior = prior_estimates(scan, 16, kPixels);
    REQUIRE(scan_prior.front().builder == "binned");
    FixedCosts scanner = prior_costs(scan, 16, kPixels);
    CHECK(choose_builder(scan, 16, kPixels, scanner).builder == "binned");
    CHECK(scanner.built.front() == "binned");
    // A room planned for 20 frames: bittner is predicted best, by less than its build costs over binned's, the cheapest
    // build predicted within 10% of it, which is measured first.
    SceneStatistics room;
    room.triangles = room.unique_triangles = 331179;
    room.box_excess = 1.59, room.reducible_cover = 3.7, room.camera_inside = true, room.box_fill = 0.34;
    constexpr int kFrames = 20;
    const std::vector<CandidateEstimate> prior = prior_estimates(room, kFrames, kPixels);
    REQUIRE(prior.size() == 6);  // every flat candidate but esc, which splits nothing here; no top level
    for (size_t i = 1; i < prior.size(); ++i) CHECK(prior[i - 1].time_to_image_ms(kFrames) <= prior[i].time_to_image_ms(kFrames));
    REQUIRE(prior.front().builder == "bittner");
    const CandidateEstimate* first = &prior.front();
    for (const CandidateEstimate& c : prior)
        if (c.time_to_image_ms(kFrames) <= 1.1 * prior.front().time_to_image_ms(kFrames) && c.build_ms < first->build_ms) first = &c;
    REQUIRE(prior.front().build_ms - first->build_ms > first->time_to_image_ms(kFrames) - prior.front().time_to_image_ms(kFrames));
    // This "machine" traces sbvh's tree at half binned's frame, which no prior expects of an architectural scene.
    FixedCosts machine = prior_costs(room, kFrames, kPixels);
    machine.costs["sbvh"].frame_ms = 0.5 * machine.costs["binned"].frame_ms;
    const AutoChoice choice = choose_builder(room, kFrames, kPixels, machine);
    CHECK(machine.built.front() == first->builder);
    CHECK(choice.candidates.front().note.find("cheapest build") != std::string::npos);
    CHECK(choice.builder == "sbvh");
    CHECK(choice.toplevel == "flat");
    CHECK(std::find(machine.discarded.begin(), machine.discarded.end(), "sbvh") == machine.discarded.end());
    CHECK(machine.discarded.size() == machine.built.size() - 1);  // every tree but the winner's is let go
    for (const CandidateEstimate& c : choice.candidates)
        if (!c.measured) CHECK(c.note.find("not measured") != std::string::npos);
    CHECK(choice.reason.find("reducible cover 3.7") != std::string::npos);
    CHECK(choice.reason.find("20 frames planned: sbvh") != std::string::npos);
    // Its own time to image: every build and sample, and the winner's frames, its 8 ms sample's reading weighed
    // against the prior, which expects sbvh's frame no faster than binned's.
    double builds = 0.0;
    for (const CandidateEstimate& c : choice.candidates)
        if (c.measured) builds += c.build_ms;
    const auto winner = std::find_if(choice.candidates.begin(), choice.candidates.end(),
                                     [](const CandidateEstimate& c) { return c.builder == "sbvh"; });
    REQUIRE(winner != choice.candidates.end());
    CHECK(winner->sampled_frame_ms == Approx(machine.costs["sbvh"].frame_ms));
    CHECK(winner->sample_weight > 0.9);
    CHECK(winner->frame_ms > winner->sampled_frame_ms);
    CHECK(winner->frame_ms < 1.05 * winner->sampled_frame_ms);
    CHECK(choice.time_to_image_ms == Approx(builds + samples_ms(choice) + kFrames * winner->frame_ms));
}

// A scene of axis-aligned quads facing a camera at the origin that looks down -z with a 90-degree field of view,
// each quad spanning [x0, x1] of the image's width (-1 to 1) and all its height at depth `depth`.
static Scene facing_quads(const std::vector<std::array<float, 3>>& quads, double aspect) {
    Scene scene;
    Mesh mesh;
    for (const auto& [x0, x1, depth] : quads) {
        const float half_width = float(aspect) * depth, z = -depth;
        const auto base = uint32_t(mesh.positions.size());
        for (const float y : {-depth, depth})
            for (const float x : {x0 * half_width, x1 * half_width}) mesh.positions.push_back({x, y, z});
        mesh.triangles.push_back({base, base + 1, base + 3});
        mesh.triangles.push_back({base, base + 3, base + 2});
    }
    mesh.objects.push_back({"quads", 0, uint32_t(mesh.triangles.size())});
    scene.meshes.push_back(std::move(mesh));
    scene.instances.push_back({0, glm::mat4(1.0f)});
    scene.camera = Camera{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 90.0f};
    return scene;
}

TEST_CASE("projected area is the image's share the triangles cover, times their depth complexity", "[auto]") {
    constexpr double kAspect = 16.0 / 9.0;
    const auto projected = [&](const std::vector<std::array<float, 3>>& quads) {
        const Scene scene = facing_quads(quads, kAspect);
        return scene_statistics(scene, flatten(scene), kAspect).projected_area;
    };
    CHECK(projected({{-1, 1, 2}}) == Approx(1.0));                     // fills the image, at any depth
    CHECK(projected({{-1, 1, 1e4f}}) == Approx(1.0));
    CHECK(projected({{-1, 1, 1e11f}}) == Approx(1.0));                 // near the largest and smallest scenes
    CHECK(projected({{-1, 1, 1e-11f}}) == Approx(1.0));                // flatten() accepts (1e12, 1e-12)
    CHECK(projected({{-1, 0, 3}}) == Approx(0.5));                     // its left half
    CHECK(projected({{-1, 1, 2}, {-1, 1, 5}}) == Approx(2.0));         // two layers: depth complexity 2
    CHECK(projected({{-1, 1, -2}}) == 0.0);                            // behind the camera
    CHECK(projected({{1.5f, 2.5f, 2}}) == 0.0);                        // right of the view
}

TEST_CASE("auto expects an object's frame to cost by the share of the image it covers", "[auto]") {
    // A ship seen from outside, 99 k triangles on 9% of a one-frame image: its frame is cheap, so lbvh's cheaper build
    // is predicted to pay more than binned's tree saves, and lbvh is measured first. The same scan covering 73% of
    // the image (as the dragon does) is predicted to trace long enough for binned's tree to pay for its build.
    SceneStatistics ship;
    ship.triangles = ship.unique_triangles = 99160, ship.box_excess = 1.6, ship.reducible_cover = 2.0, ship.box_fill = 0.35;
    ship.projected_area = 0.09;
    CHECK(prior_estimates(ship, 1, kPixels).front().builder == "lbvh");
    FixedCosts machine = prior_costs(ship, 1, kPixels);
    CHECK(choose_builder(ship, 1, kPixels, machine).builder == "lbvh");
    CHECK(machine.built.front() == "lbvh");
    SceneStatistics covering = ship;
    covering.projected_area = 0.73;
    CHECK(prior_estimates(covering, 1, kPixels).front().builder == "binned");
    // Past the largest area the per-pixel cost was fitted on, it does not grow further.
    SceneStatistics deep = ship, deeper = ship;
    deep.projected_area = 2.1, deeper.projected_area = 40.0;
    CHECK(prior_estimates(deep, 1, kPixels).front().frame_ms == Approx(prior_estimates(deeper, 1, kPixels).front().frame_ms));
}

TEST_CASE("auto weighs a sample's reading against the priors by the sample's length", "[auto]") {
    // A small scan filling the image (its front and back faces: projected area 1.6) planned for one frame, traced
    // through one pixel in a thousand: lbvh's sample reads its frame at 0.9x binned's, where the priors expect 1.09x.
    // Every candidate but bittner fits the calibration budget.
    SceneStatistics scan;
    scan.triangles = scan.unique_triangles = 3732, scan.box_excess = 2.05, scan.reducible_cover = 2.0, scan.box_fill = 0.35;
    scan.projected_area = 1.6;
    const auto choose = [&](uint64_t pixels) {
        FixedCosts machine = prior_costs(scan, 1, pixels);
        machine.costs["lbvh"].frame_ms = 0.9 * machine.costs["binned"].frame_ms;
        machine.share = 0.001;
        const AutoChoice choice = choose_builder(scan, 1, pixels, machine);
        CHECK(std::find(machine.built.begin(), machine.built.end(), "lbvh") != machine.built.end());
        return choice.builder;
    };
    CHECK(sample_weight(0.15) < 0.5);
    CHECK(choose(kPixels) == "binned");       // samples of 0.16 ms: the priors outweigh them
    CHECK(sample_weight(4.0) > 0.9);
    CHECK(choose(30 * kPixels) == "lbvh");    // 4.7 ms: the reading outweighs the priors
}

TEST_CASE("sbvh's predicted frame falls with binned's sibling overlap, down to its floor", "[auto]") {
    CHECK(sbvh_frame_from_overlap(0.0) == 1.0);
    CHECK(sbvh_frame_from_overlap(0.17) == 1.0);
    CHECK(sbvh_frame_from_overlap(0.18) < 1.0);
    CHECK(sbvh_frame_from_overlap(0.215) < sbvh_frame_from_overlap(0.18));
    CHECK(sbvh_frame_from_overlap(0.2) == Approx(0.886));
    CHECK(sbvh_frame_from_overlap(0.5) == Approx(0.83));  // no extrapolation past the largest gain fitted
}

TEST_CASE("auto judges sbvh by the sibling overlap of binned's tree, once binned is measured", "[auto]") {
    // sibenik's statistics planned for one frame: architecture without dense boxes, where the class prior expects
    // sbvh to trace as fast as binned; on this machine it traces in 0.92x.
    SceneStatistics room;
    room.triangles = room.unique_triangles = 75284, room.box_excess = 1.61, room.reducible_cover = 3.6;
    room.box_fill = 0.36, room.camera_inside = true;
    const auto choose = [&](double overlap) {
        FixedCosts machine = prior_costs(room, 1, kPixels);
        machine.costs["sbvh"].frame_ms = 0.92 * machine.costs["binned"].frame_ms;
        machine.overlap = overlap;
        const AutoChoice choice = choose_builder(room, 1, kPixels, machine);
        CHECK(machine.built.front() == "binned");
        CHECK(choice.sibling_overlap == overlap);
        return choice;
    };
    // No tree to read, or one whose siblings overlap as little as conference's: the build is not worth its
    // predicted gain, nor within the budget.
    CHECK(choose(-1.0).builder == "binned");
    CHECK(choose(0.16).builder == "binned");
    // Siblings that overlap as much as crytek-sponza's: sbvh is measured, and wins.
    const AutoChoice overlapping = choose(0.215);
    CHECK(overlapping.builder == "sbvh");
    CHECK(overlapping.reason.find("sibling overlap 0.215") != std::string::npos);
    // Sliver fields keep their class priors: the overlap is not read.
    SceneStatistics slivers = room;
    slivers.box_excess = 6.75;
    FixedCosts machine = prior_costs(slivers, 1, kPixels);
    machine.overlap = 0.215;
    CHECK(choose_builder(slivers, 1, kPixels, machine).sibling_overlap < 0.0);
}

TEST_CASE("auto stays within 10% of the best time to image when the priors hold", "[auto]") {
    const SceneStatistics sponza = sponza_statistics();
    for (const int frames : {1, 16, 256}) {
        FixedCosts machine = prior_costs(sponza, frames, kPixels);
        const AutoChoice choice = choose_builder(sponza, frames, kPixels, machine);
        const CandidateEstimate best = prior_estimates(sponza, frames, kPixels).front();
        CAPTURE(frames, choice.builder, best.builder);
        CHECK(choice.time_to_image_ms <= 1.1 * best.time_to_image_ms(frames));
        CHECK(choice.calibration_ms <= choice.budget_ms + samples_ms(choice) + best.build_ms);
    }
    // One frame: bittner's second-long build can neither pay for itself nor fit the budget, so it is never built.
    FixedCosts machine = prior_costs(sponza, 1, kPixels);
    choose_builder(sponza, 1, kPixels, machine);
    CHECK(std::find(machine.built.begin(), machine.built.end(), "bittner") == machine.built.end());
    // 256 frames: the budget is seconds, and every candidate is measured.
    machine = prior_costs(sponza, 256, kPixels);
    choose_builder(sponza, 256, kPixels, machine);
    CHECK(machine.built.size() == 6);
}

TEST_CASE("auto splits where splitting pays on this machine, not where the statistics alone say so", "[auto]") {
    // Slivers (the foliage's statistics): the priors expect splits to pay 2.7x.
    SceneStatistics foliage;
    foliage.triangles = foliage.unique_triangles = 48000, foliage.box_excess = 24.0, foliage.reducible_cover = 54.1;
    foliage.box_fill = 0.031;
    FixedCosts no_gain = prior_costs(foliage, 256, kPixels);
    for (const char* split : {"sbvh", "esc", "bonsai-split"}) no_gain.costs[split].frame_ms = 1.2 * no_gain.costs["binned"].frame_ms;
    // At 256 frames every candidate is measured: the least frame wins, a tree that splits nothing (bittner's, 0.87x).
    const std::string chosen = choose_builder(foliage, 256, kPixels, no_gain).builder;
    CHECK(chosen == "bittner");
    for (const auto& [name, costs] : no_gain.costs) CHECK(no_gain.costs[chosen].frame_ms <= costs.frame_ms);
    // Where they do pay, the one with the best frame wins many frames.
    FixedCosts gain = prior_costs(foliage, 256, kPixels);
    gain.costs["sbvh"].frame_ms = 0.9 * gain.costs["esc"].frame_ms;
    CHECK(choose_builder(foliage, 256, kPixels, gain).builder == "sbvh");
    FixedCosts one = prior_costs(foliage, 1, kPixels);
    CHECK(choose_builder(foliage, 1, kPixels, one).time_to_image_ms <= 1.1 * prior_estimates(foliage, 1, kPixels).front().time_to_image_ms(1));
}

TEST_CASE("auto expects esc to lead where slivers cross the scene, and sbvh where they cluster", "[auto]") {
    const auto fastest_frame = [](const Scene& scene) {
        const std::vector<CandidateEstimate> candidates = prior_estimates(scene_statistics(scene, flatten(scene), 4.0 / 3.0), 256, kPixels);
        return std::min_element(candidates.begin(), candidates.end(), [](const CandidateEstimate& a, const CandidateEstimate& b) {
                   return a.frame_ms < b.frame_ms;
               })->builder;
    };
    for (const char* crossing : {"gen:cylinders?tris=3000&seed=2", "gen:cylinders?tris=50000&seed=7"})
        CHECK(fastest_frame(load_scene(crossing)) == "esc");
    for (const char* clustered : {"gen:foliage?tris=3000&seed=2", "gen:foliage?tris=48000&seed=4"})
        CHECK(fastest_frame(load_scene(clustered)) == "sbvh");
}

TEST_CASE("auto measures esc only where its automatic SA_max splits", "[auto]") {
    const auto has_esc = [](const SceneStatistics& stats) {
        const std::vector<CandidateEstimate> candidates = prior_estimates(stats, 16, kPixels);
        return std::any_of(candidates.begin(), candidates.end(), [](const CandidateEstimate& c) { return c.builder == "esc"; });
    };
    SceneStatistics stats = sponza_statistics();
    CHECK_FALSE(has_esc(stats));
    stats.box_fill = 0.099;
    CHECK(has_esc(stats));
    // The statistics' fill is the one esc's rule reads: generated slivers split, a generated room does not.
    const Scene foliage = load_scene("gen:foliage?tris=3000&seed=2"), room = load_scene("gen:room?tris=3000&seed=2");
    CHECK(scene_statistics(foliage, flatten(foliage), 4.0 / 3.0).box_fill < kEscMaxFillToSplit);
    CHECK(scene_statistics(room, flatten(room), 4.0 / 3.0).box_fill > kEscMaxFillToSplit);
    const FlatScene flat = flatten(foliage);
    CHECK(std::isfinite(automatic_sa_max(flat.triangles, make_prim_refs(flat.triangles))));
}

TEST_CASE("auto chooses two-level only with instances, and only two-level past the flattening limit", "[auto]") {
    SceneStatistics zoo = sponza_statistics();
    zoo.unique_triangles = 150000, zoo.triangles = 64 * zoo.unique_triangles, zoo.camera_inside = false;
    const std::vector<CandidateEstimate> zoo_candidates = prior_estimates(zoo, 16, kPixels);
    CHECK(std::any_of(zoo_candidates.begin(), zoo_candidates.end(), [](const CandidateEstimate& c) { return c.toplevel == "rebraid"; }));
    FixedCosts machine = prior_costs(zoo, 16, kPixels);
    CHECK(choose_builder(zoo, 16, kPixels, machine).toplevel == "rebraid");
    zoo.triangles = 1024 * zoo.unique_triangles;  // 150 M triangles flattened: past the limit
    const std::vector<CandidateEstimate> only = prior_estimates(zoo, 1, kPixels);
    REQUIRE(only.size() == 1);
    CHECK(only.front().toplevel == "rebraid");
    for (const CandidateEstimate& c : prior_estimates(sponza_statistics(), 1, kPixels)) CHECK(c.toplevel == "flat");
    // The same rule decides whether auto prepares PrimRefs for a flat candidate at all.
    CHECK_FALSE(flat_candidates(zoo.triangles, zoo.unique_triangles));
    CHECK(flat_candidates(64 * zoo.unique_triangles, zoo.unique_triangles));
    CHECK(flat_candidates(2 * kMaxFlattenedTriangles, 2 * kMaxFlattenedTriangles));  // nothing instanced: flat only
}

TEST_CASE("auto's explanation lists every candidate and the choice", "[auto]") {
    const SceneStatistics sponza = sponza_statistics();
    FixedCosts machine = prior_costs(sponza, 16, kPixels);
    const AutoChoice choice = choose_builder(sponza, 16, kPixels, machine);
    const std::string text = explain(choice, 16);
    for (const CandidateEstimate& c : choice.candidates) CHECK(text.find(c.note) != std::string::npos);
    CHECK(choice.candidates.size() == 6);
    CHECK(text.find("chosen: " + choice.builder) != std::string::npos);
    CHECK(text.find("TTI@16") != std::string::npos);
}

TEST_CASE("auto's budget counts a sample's warm-up and its retrace where the first trace is too short to time", "[auto]") {
    // Every sample after the first tree's is preceded by a warm-up of one tile in kTreeWarmUpStride.
    const auto warm_up = [](double frame_ms) { return frame_ms / kTreeWarmUpStride; };
    // forklift at 16 frames: a 30 ms frame, one tile in 32 (0.94 ms), then the retrace of 6.25 ms.
    CHECK(expected_sample_cost_ms(30.0, 32, 5.0) == Approx(warm_up(30.0) + 30.0 / 32 + kSampleAim * 5.0));
    // A first trace long enough is all of it but the warm-up; so is one with no minimum (one frame planned).
    CHECK(expected_sample_cost_ms(400.0, 32, 5.0) == Approx(warm_up(400.0) + 12.5));
    CHECK(expected_sample_cost_ms(30.0, 128, 0.0) == Approx(warm_up(30.0) + 30.0 / 128));
    // The retrace is at least twice the first, and at most the whole frame.
    CHECK(expected_sample_cost_ms(150.0, 32, 5.0) == Approx(warm_up(150.0) + 3.0 * 150.0 / 32));
    CHECK(expected_sample_cost_ms(4.0, 32, 5.0) == Approx(warm_up(4.0) + 4.0 / 32 + 4.0));
    CHECK(expected_sample_cost_ms(4.0, 1, 5.0) == Approx(warm_up(4.0) + 4.0));
}

TEST_CASE("a sample too short to time is traced again with as many tiles as its rate says it needs", "[auto]") {
    // 0.9 ms through one tile in 32, where 5 ms are needed: 32 x 0.9 / 6.25 = 4.6, so one tile in 4 (about 7 ms).
    CHECK(next_sample_stride(32, 0.9, 5.0) == 4);
    // At least twice the tiles, however close the sample came, and never fewer.
    CHECK(next_sample_stride(32, 4.9, 5.0) == 16);
    CHECK(next_sample_stride(32, 5.0 * kSampleAim, 5.0) == 16);
    // A sample that took no time, or a negative clock difference, asks for the whole frame; so does a stride of 1.
    CHECK(next_sample_stride(128, 0.0, 5.0) == 1);
    CHECK(next_sample_stride(128, -1.0, 5.0) == 1);
    CHECK(next_sample_stride(1, 0.1, 5.0) == 1);
    CHECK(next_sample_stride(2, 0.1, 5.0) == 1);
    // A rate that needs exactly one tile in 8 gets it.
    CHECK(next_sample_stride(128, 8.0 * kSampleAim * 5.0 / 128.0, 5.0) == 8);
}

TEST_CASE("a frame's sample traces the frame's own paths in its tiles, and nothing else", "[auto]") {
    const Scene scene = load_scene("gen:box?tris=2000&seed=3");
    const FlatScene flat = flatten(scene);
    const auto accel = make_canopy_accelerator(scene, flat, CanopyOptions{});
    accel->prepare();
    accel->build();
    FrameSettings whole_frame, sample;
    whole_frame.width = sample.width = 45, whole_frame.height = sample.height = 30;  // tiles cut by both edges
    sample.sample_stride = 4;
    const PinholeCamera camera(scene_camera(scene, flat), 45, 30);
    Image whole(45, 30), sampled(45, 30);
    render(*accel, ShadingScene{flat, whole_frame}, camera, 3, whole);
    render(*accel, ShadingScene{flat, sample}, camera, 3, sampled);
    // A tile in 4 of the 6 x 4 tiles of 8 x 8 pixels: one in each run of 4, the edge tiles cut to the frame.
    std::set<std::pair<int, int>> in_sample;
    for (uint64_t k = 0; k < 6; ++k) {
        const uint64_t tile = sample_tile(k, 4);
        CHECK(tile / 4 == k);
        for (int y = 8 * int(tile / 6); y < std::min(8 * int(tile / 6) + 8, 30); ++y)
            for (int x = 8 * int(tile % 6); x < std::min(8 * int(tile % 6) + 8, 45); ++x) in_sample.insert({x, y});
    }
    CHECK(traced_pixels(45, 30, 4) == in_sample.size());
    CHECK(traced_pixels(45, 30, 1) == 45u * 30u);
    const std::vector<float> all = whole.average(1), part = sampled.average(1);
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 45; ++x)
            for (int c = 0; c < 3; ++c) {
                const size_t i = (size_t(y) * 45 + size_t(x)) * 3 + size_t(c);
                CHECK(part[i] == (in_sample.count({x, y}) ? all[i] : 0.0f));
            }
}

TEST_CASE("auto builds the tree it chose on the machine at hand", "[auto]") {
    // The choice is a registered builder, and the accelerator built with it reports it.
    const Scene scene = load_scene("gen:box?tris=2000&seed=3");
    const FlatScene flat = flatten(scene);
    CanopyOptions options;
    options.builder = "auto";
    const auto accel = make_canopy_accelerator(scene, flat, options);
    accel->prepare();
    accel->build();
    CHECK(accel->builder() == "auto");
    const std::string chosen = accel->chosen();  // an optimiser names its start tree: "bittner<lbvh"
    CHECK_NOTHROW(find_builder(chosen.substr(0, chosen.find('<'))));
    CHECK_THROWS_WITH(make_canopy_accelerator(flat, options), Catch::Contains("auto"));
}

TEST_CASE("the library's auto times its candidates on random rays through the scene", "[auto]") {
    const Scene scene = load_scene("gen:box?tris=2000&seed=3");
    const FlatScene flat = flatten(scene);
    const auto sample = random_ray_sample(flat, 4096);
    CHECK(sample->pixels() == 4096u);
    CHECK(sample->share(1) == 1.0);
    CHECK(sample->share(4) == Approx(0.25));
    CHECK(sample->share(1000) == Approx(64.0 / 4096.0));  // one block of rays at least
    CanopyOptions options;
    options.builder = "auto";
    options.auto_sample = sample;
    const auto accel = make_canopy_accelerator(scene, flat, options);
    accel->prepare();
    accel->build();
    REQUIRE(accel->auto_choice());
    for (const CandidateEstimate& c : accel->auto_choice()->candidates)
        if (c.measured) CHECK(c.sampled_frame_ms > 0.0);
}
