// The split builders (sbvh, presplit, esc): every reference's box lies inside its triangle's box and the boxes of
// a triangle's references together hold the whole triangle, also for slivers, huge overlapping triangles and
// extreme coordinates; SBVH's memory cap holds; bad options are refused; brute-force agreement on adversarial input.
#include "accel/builders/binned_sah.h"
#include "accel/builders/early_split_clipping.h"
#include "accel/builders/presplit.h"
#include "accel/builders/sbvh.h"
#include "oracle.h"
#include "scenes/pathological.h"
#include "renderer/frames.h"

#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>

using namespace canopy;
using namespace canopy::test;

namespace {

// Long diagonal slivers, huge triangles overlapping each other across the whole scene, a few ordinary ones, and
// some of them again scaled to coordinates near 1e15 and 1e-15 (box areas stay
// finite and non-zero in float).
std::vector<Triangle> adversarial_scene(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    auto point = [&] { return Vec3(u(rng), u(rng), u(rng)); };
    std::vector<Triangle> tris;
    for (int i = 0; i < 300; ++i) {  // slivers from corner region to corner region, 1e-4 wide
        const Vec3 a = point(), b = -a + 0.1f * point();
        tris.push_back({a, b, b + Vec3(1e-4f, 0, 1e-4f)});
    }
    for (int i = 0; i < 200; ++i) tris.push_back({10.0f * point(), 10.0f * point(), 10.0f * point()});  // huge
    for (int i = 0; i < 300; ++i) {
        const Vec3 c = point();
        tris.push_back({c, c + 0.02f * point(), c + 0.02f * point()});
    }
    const size_t base = tris.size();
    for (float scale : {1e15f, 1e-15f})
        for (size_t i = 0; i < base; i += 7) tris.push_back({scale * tris[i].v0, scale * tris[i].v1, scale * tris[i].v2});
    return tris;
}

bool inside(const BBox& inner, const BBox& outer) {
    return glm::all(glm::greaterThanEqual(inner.lower, outer.lower)) && glm::all(glm::lessThanEqual(inner.upper, outer.upper));
}

bool contains(const BBox& box, const Vec3& p) {
    return glm::all(glm::lessThanEqual(box.lower, p)) && glm::all(glm::lessThanEqual(p, box.upper));
}

// Vertices and random points of the triangle, in float (each coordinate clamped to the triangle's box).
std::vector<Vec3> sample_points(const Triangle& t, std::mt19937& rng) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<Vec3> points{t.v0, t.v1, t.v2};
    const BBox box = BBox::of(t);
    for (int i = 0; i < 24; ++i) {
        float a = u(rng), b = u(rng);
        if (a + b > 1.0f) a = 1.0f - a, b = 1.0f - b;
        points.push_back(glm::clamp(t.v0 + a * (t.v1 - t.v0) + b * (t.v2 - t.v0), box.lower, box.upper));
    }
    return points;
}

// Each triangle's pieces are non-empty and (references, not leaves) inside its box; sampled points of the triangle each lie in one of
// its pieces, up to a float's rounding of the sample itself (pieces widened by 1e-6 of the triangle's coordinates).
void check_pieces(std::span<const Triangle> tris, const std::vector<std::vector<BBox>>& pieces, const std::string& what,
                  bool inside_triangle_box = true) {
    INFO(what);
    std::mt19937 rng(11);
    size_t outside = 0, uncovered = 0, missing = 0;
    for (size_t t = 0; t < tris.size(); ++t) {
        const BBox whole = BBox::of(tris[t]);
        missing += pieces[t].empty();
        for (const BBox& b : pieces[t]) outside += b.empty() || (inside_triangle_box && !inside(b, whole));
        for (const Vec3& p : sample_points(tris[t], rng)) {
            bool covered = false;
            for (BBox b : pieces[t]) {
                const Vec3 slack = 1e-6f * glm::max(glm::abs(whole.lower), glm::abs(whole.upper));
                b.lower -= slack;
                b.upper += slack;
                covered = covered || contains(b, p);
            }
            uncovered += !covered;
        }
    }
    CHECK(missing == 0);
    CHECK(outside == 0);
    CHECK(uncovered == 0);
}

std::vector<std::vector<BBox>> pieces_of(const std::vector<PrimRef>& refs, size_t triangles) {
    std::vector<std::vector<BBox>> pieces(triangles);
    for (const PrimRef& r : refs) pieces[r.prim].push_back(r.bounds());
    return pieces;
}

// The boxes of the leaves holding each triangle: SBVH's pieces as the tree keeps them.
std::vector<std::vector<BBox>> leaf_pieces(const Bvh& bvh, size_t triangles) {
    std::vector<std::vector<BBox>> pieces(triangles);
    for (const BvhNode& node : bvh.nodes)
        if (node.is_leaf())
            for (uint32_t i = node.index; i < node.index + node.count; ++i) pieces[bvh.refs[i]].push_back(node.bounds);
    return pieces;
}

// Leaf boxes need not lie inside the triangle's box (a leaf holds other pieces too); they must meet it.
void check_leaf_boxes_meet(const Bvh& bvh, std::span<const Triangle> tris) {
    size_t apart = 0;
    for (const BvhNode& node : bvh.nodes)
        if (node.is_leaf())
            for (uint32_t i = node.index; i < node.index + node.count; ++i) {
                const BBox t = BBox::of(tris[bvh.refs[i]]);
                apart += !(glm::all(glm::lessThanEqual(node.bounds.lower, t.upper)) && glm::all(glm::lessThanEqual(t.lower, node.bounds.upper)));
            }
    CHECK(apart == 0);
}

}  // namespace

TEST_CASE("presplit pieces lie in their triangle and cover it; the budget holds", "[builders][split]") {
    const std::vector<Triangle> tris = adversarial_scene(1);
    for (float budget : {0.1f, 0.5f, 3.0f}) {
        const std::vector<PrimRef> refs = presplit_refs(tris, make_prim_refs(tris), budget);
        INFO("budget " << budget);
        CHECK(refs.size() > tris.size());
        CHECK(refs.size() <= tris.size() + size_t(budget * float(tris.size())));
        check_pieces(tris, pieces_of(refs, tris.size()), "presplit");
    }
    CHECK(presplit_refs(tris, make_prim_refs(tris), 0.0f).size() == tris.size());
    CHECK_THROWS_AS(presplit_refs(tris, make_prim_refs(tris), -0.5f), std::invalid_argument);
}

TEST_CASE("early split clipping pieces lie in their triangle, cover it and respect SA_max", "[builders][split]") {
    const std::vector<Triangle> tris = adversarial_scene(2);
    for (float sa_max : {1.0f, 0.01f}) {
        const std::vector<PrimRef> refs = early_split_clip_refs(tris, make_prim_refs(tris), sa_max);
        INFO("SA_max " << sa_max);
        CHECK(refs.size() > tris.size());
        check_pieces(tris, pieces_of(refs, tris.size()), "esc");
        // Every piece is within SA_max where the depth limit allows: 10 halvings shrink a box's area at least
        // 64-fold (a third of them on each axis of a diagonal sliver), so triangles up to 64 SA_max get there.
        size_t too_big = 0;
        for (const PrimRef& r : refs)
            too_big += r.bounds().area() > sa_max && BBox::of(tris[r.prim]).area() <= 64.0f * sa_max && !esc_keeps_whole(tris[r.prim]);
        CHECK(too_big == 0);
    }
    CHECK_THROWS_AS(early_split_clip_refs(tris, make_prim_refs(tris), 0.0f), std::invalid_argument);
    BuildSettings negative;
    negative.params.set(kEscSaMaxKey, "-1");
    CHECK_THROWS_AS(build_esc(BuildInput{tris, make_prim_refs(tris)}, negative), std::invalid_argument);
}

TEST_CASE("SA_max parses as auto, a box area or median ideal areas, and means the same at any scale", "[builders][split]") {
    CHECK(parse_sa_max("auto") == SaMax{});
    CHECK(parse_sa_max("12.5") == SaMax{SaMax::Unit::Absolute, 12.5f});
    CHECK(parse_sa_max("8x") == SaMax{SaMax::Unit::MedianIdealArea, 8.0f});
    for (const char* text : {"auto", "12.5", "8x", "0.25x"}) CHECK(sa_max_name(parse_sa_max(text)) == text);
    for (const char* bad : {"", "x", "0", "-1", "0x", "nan", "inf", "8y", "8xx", "1e40", "auto8"}) {
        INFO(bad);
        CHECK_THROWS_AS(parse_sa_max(bad), std::invalid_argument);
    }
    // A multiple of the median ideal area splits a scene and the same scene scaled by 2^20 into the same pieces.
    const FlatScene slivers = flatten(load_scene("gen:cylinders?tris=4000&seed=5"));
    std::vector<Triangle> scaled = slivers.triangles;
    for (Triangle& t : scaled) t = {t.v0 * 1048576.0f, t.v1 * 1048576.0f, t.v2 * 1048576.0f};
    const SaMax four{SaMax::Unit::MedianIdealArea, 4.0f};
    const float at_one = resolve_esc_area(slivers.triangles, make_prim_refs(slivers.triangles), four);
    const float at_scale = resolve_esc_area(scaled, make_prim_refs(scaled), four);
    CHECK(at_scale == Approx(at_one * 1048576.0f * 1048576.0f).epsilon(1e-5));
    const size_t pieces = early_split_clip_refs(slivers.triangles, make_prim_refs(slivers.triangles), at_one).size();
    CHECK(pieces > slivers.triangles.size());
    CHECK(early_split_clip_refs(scaled, make_prim_refs(scaled), at_scale).size() == pieces);
    // Halving SA_max never cuts fewer pieces.
    const SaMax two{SaMax::Unit::MedianIdealArea, 2.0f};
    CHECK(early_split_clip_refs(slivers.triangles, make_prim_refs(slivers.triangles),
                                resolve_esc_area(slivers.triangles, make_prim_refs(slivers.triangles), two)).size() >= pieces);
}

TEST_CASE("automatic SA_max splits scenes of slivers and leaves well-filled boxes alone", "[builders][split]") {
    const FlatScene slivers = flatten(load_scene("gen:cylinders?tris=20000&seed=3"));
    const float sa_max = automatic_sa_max(slivers.triangles, make_prim_refs(slivers.triangles));
    REQUIRE(std::isfinite(sa_max));
    CHECK(early_split_clip_refs(slivers.triangles, make_prim_refs(slivers.triangles), sa_max).size() > 2 * slivers.triangles.size());
    for (const char* spec : {"gen:surface?tris=20000&seed=3", "gen:box?tris=20000&seed=3"}) {
        const FlatScene filled = flatten(load_scene(spec));
        INFO(spec);
        CHECK(std::isinf(automatic_sa_max(filled.triangles, make_prim_refs(filled.triangles))));
        const Bvh esc = build_esc(BuildInput{filled.triangles, make_prim_refs(filled.triangles)}, {});
        CHECK(esc.refs.size() == filled.triangles.size());
        // Nothing split, esc is binned SAH over the same references: the same tree, node for node.
        const Bvh binned = build_binned_sah(BuildInput{filled.triangles, make_prim_refs(filled.triangles)}, {});
        CHECK(esc.refs == binned.refs);
        REQUIRE(esc.nodes.size() == binned.nodes.size());
        CHECK(std::memcmp(esc.nodes.data(), binned.nodes.data(), esc.nodes.size() * sizeof(BvhNode)) == 0);
    }
}

TEST_CASE("early split clipping leaves lines and points whole and keeps needles within the reference budget",
          "[builders][split]") {
    const std::vector<Triangle> lines = zero_area_triangles(20000);
    for (const Triangle& t : lines) REQUIRE(esc_keeps_whole(t));
    CHECK(early_split_clip_refs(lines, make_prim_refs(lines), 1e-12f).size() == lines.size());
    // The smallest SA_max would split every needle into up to 2^10 pieces: a doubling of it that fits the budget
    // of 4 a triangle is used instead, and the needles are still split.
    const std::vector<Triangle> needles = parallel_needles(20000);
    const auto budget = uint64_t(kMaxEscReferencesPerTriangle * double(needles.size()));
    const size_t pieces = early_split_clip_refs(needles, make_prim_refs(needles), 1e-12f, budget).size();
    CHECK(pieces <= budget);
    CHECK(pieces > needles.size());
    CHECK(early_split_clip_count(needles, make_prim_refs(needles), 1e-12f) > budget);
}

TEST_CASE("sbvh leaves of a triangle cover it; the reference cap holds", "[builders][split]") {
    const std::vector<Triangle> tris = adversarial_scene(3);
    const Bvh bvh = build_sbvh(BuildInput{tris, make_prim_refs(tris)}, BuildSettings{});
    CHECK(bvh.refs.size() > tris.size());
    CHECK(bvh.refs.size() <= 2 * tris.size());
    CHECK(bvh.split.reference_capacity == 2 * tris.size());
    check_leaf_boxes_meet(bvh, tris);
    check_pieces(tris, leaf_pieces(bvh, tris.size()), "sbvh leaves", false);
}

TEST_CASE("sbvh's memory cap holds on thousands of huge overlapping slivers", "[builders][split]") {
    // Parallel slivers along the cube's diagonal, side by side: every object split leaves children whose boxes
    // overlap almost entirely, every spatial split shrinks them, all the way down, so only the cap stops SBVH.
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<Triangle> tris;
    for (int i = 0; i < 4000; ++i) {
        const Vec3 o(u(rng), u(rng), u(rng));
        tris.push_back({o - Vec3(2.0f), o + Vec3(2.0f), o + Vec3(2.0f + 1e-3f, 2.0f - 1e-3f, 2.0f)});
    }
    for (float cap : {2.0f, 1.25f, 1.0f}) {
        const Bvh bvh = build_sbvh_with(BuildInput{tris, make_prim_refs(tris)}, BuildSettings{}, SbvhSettings{1e-5f, cap});
        INFO("cap " << cap);
        CHECK(bvh.refs.size() <= size_t(cap * float(tris.size())));
        CHECK(bvh.split.reference_capacity == uint64_t(cap * float(tris.size())));
        // At 2 the cap is what stops the splitting (unlimited, SBVH splits far more here). At 1.25 the spare
        // slots are fewer than one split of the root would take, and each subtree only gets its share of them.
        if (cap == 2.0f) CHECK(bvh.refs.size() > size_t((cap - 0.25f) * float(tris.size())));
        check_leaf_boxes_meet(bvh, tris);
    }
    CHECK_THROWS_AS(build_sbvh_with(BuildInput{tris, make_prim_refs(tris)}, {}, SbvhSettings{1e-5f, 0.5f}), std::invalid_argument);
    CHECK_THROWS_AS(build_sbvh_with(BuildInput{tris, make_prim_refs(tris)}, {}, SbvhSettings{-1.0f, 2.0f}), std::invalid_argument);
}

TEST_CASE("sbvh's alpha: the papers' 1e-5 tries spatial splits where canopy's 1e-3 does not", "[builders][split]") {
    // Parallel slivers side by side in a unit cube above a floor 100 wide: object splits leave children whose boxes
    // overlap by about 3e-4 of the root's area, so only the papers' alpha tries the spatial splits that pay there.
    std::vector<Triangle> tris{{Vec3(-50, -50, -1), Vec3(50, -50, -1), Vec3(50, 50, -1)}, {Vec3(-50, -50, -1), Vec3(50, 50, -1), Vec3(-50, 50, -1)}};
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-0.05f, 0.05f);
    for (int i = 0; i < 500; ++i) {
        const Vec3 o(u(rng), u(rng), u(rng));
        tris.push_back({o - Vec3(0.5f), o + Vec3(0.5f), o + Vec3(0.5f + 1e-3f, 0.5f - 1e-3f, 0.5f)});
    }
    BuildSettings papers;
    papers.params.set("alpha", "1e-5");
    const Bvh at_papers = build_sbvh(BuildInput{tris, make_prim_refs(tris)}, papers);
    const Bvh at_default = build_sbvh(BuildInput{tris, make_prim_refs(tris)}, BuildSettings{});
    const Bvh no_spatial = build_sbvh_with(BuildInput{tris, make_prim_refs(tris)}, BuildSettings{}, SbvhSettings{1e30f, 2.0f});
    // (The default splits where the overlap is larger: "sbvh leaves of a triangle cover it" above.)
    CHECK(at_papers.refs.size() > tris.size());
    CHECK(at_default.refs.size() == tris.size());
    CHECK(no_spatial.refs.size() == tris.size());
    check_leaf_boxes_meet(at_papers, tris);
    check_leaf_boxes_meet(at_default, tris);
    // The accelerator takes it for sbvh only, finite and >= 0.
    FlatScene flat;
    flat.triangles = tris;
    CHECK_THROWS_WITH(make_canopy_accelerator(flat, {"binned:alpha=1e-5", "", "bvh8"}), Catch::Contains("no parameter 'alpha'"));
    for (const char* spec : {"sbvh:alpha=-1", "sbvh:alpha=inf", "sbvh:alpha=1e-5x"}) {
        INFO(spec);
        CHECK_THROWS_WITH(make_canopy_accelerator(flat, {spec, "", "bvh8"}), Catch::Contains("sbvh alpha"));
    }
    CHECK(make_canopy_accelerator(flat, {"sbvh:alpha=1e-5", "", "bvh8"})->builder() == "sbvh:alpha=1e-5");
    CHECK(make_canopy_accelerator(flat, {"sbvh:alpha=0.001", "", "bvh8"})->builder() == "sbvh");  // the default
}

TEST_CASE("split builders agree with brute force on adversarial input", "[oracle][split]") {
    const std::vector<Triangle> tris = adversarial_scene(4);
    check_against_oracle(tris, random_rays(tris, 4000, 9), "adversarial splits");
}
