// SAH-guided split partitioning (Ganestam and Doggett 2016, sec. 3.2 and 4.1): the split references' bounds, the
// in-place growing memory, and independence of the number of threads. The trees built on it are checked by the
// oracle and invariant tests through the registry.
#include "accel/builder.h"
#include "accel/builders/split_partitioning.h"

#include <catch2/catch.hpp>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <random>
#include <stdexcept>

using namespace canopy;

namespace {

// Long thin triangles along x across the whole scene among small ones: nearly every cut on x crosses the slivers,
// and clipping them pays, so references multiply and partitions outgrow their free space.
std::vector<Triangle> slivers_among_small_triangles(int slivers, int small, float scale, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Triangle> tris;
    for (int i = 0; i < slivers; ++i) {
        const Vec3 a(-100.0f, unit(rng), unit(rng));
        tris.push_back({a * scale, (a + Vec3(200.0f, 1e-3f, 0.0f)) * scale, (a + Vec3(200.0f, 0.0f, 1e-6f)) * scale});
    }
    for (int i = 0; i < small; ++i) {
        const Vec3 a(unit(rng) * 200.0f - 100.0f, unit(rng), unit(rng));
        tris.push_back({a * scale, (a + Vec3(0.05f, 0.0f, 0.0f)) * scale, (a + Vec3(0.0f, 0.05f, 0.05f)) * scale});
    }
    return tris;
}

// Nearly degenerate triangles (needles, near-collinear vertices, one-ulp widths) at tiny and huge coordinates.
std::vector<Triangle> nearly_degenerate_and_extreme(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::vector<Triangle> tris;
    for (float scale : {1e-30f, 1.0f, 1e30f}) {
        for (int i = 0; i < 400; ++i) {
            const Vec3 a(unit(rng), unit(rng), unit(rng));
            const Vec3 b = a + Vec3(1.5f, unit(rng), 0.0f);
            const Vec3 mid = 0.5f * (a + b);
            const Vec3 c(std::nextafter(mid.x, 10.0f), mid.y, std::nextafter(mid.z, 10.0f));  // one ulp off the edge
            tris.push_back({a * scale, b * scale, c * scale});
            tris.push_back({a * scale, (a + Vec3(2.0f, 1e-7f, 0.0f)) * scale, (a + Vec3(2.0f, 0.0f, 1e-7f)) * scale});
        }
    }
    return tris;
}

// The box grown by one float step outwards on every side: room for the error of a point computed in double.
bool contains_within_a_step(const BBox& box, const glm::dvec3& p) {
    for (int k = 0; k < 3; ++k) {
        if (p[k] < double(std::nextafter(box.lower[k], -INFINITY)) || p[k] > double(std::nextafter(box.upper[k], INFINITY)))
            return false;
    }
    return true;
}

// Every ref lies inside its triangle's box, and every point of every triangle lies in one of its refs: the split
// halves together cover the triangle, each half the part on its side of the planes.
void check_split_references(std::span<const Triangle> tris, const Partitioning& partitioning) {
    std::vector<std::vector<BBox>> pieces(tris.size());
    size_t outside = 0;
    for (const auto& partition : partitioning.partitions) {
        for (const PrimRef& ref : partition) {
            REQUIRE(ref.prim < tris.size());
            const BBox whole = BBox::of(tris[ref.prim]);
            outside += !(glm::all(glm::lessThanEqual(whole.lower, ref.lower)) &&
                         glm::all(glm::greaterThanEqual(whole.upper, ref.upper)) && !ref.bounds().empty());
            pieces[ref.prim].push_back(ref.bounds());
        }
    }
    CHECK(outside == 0);
    size_t uncovered = 0;
    constexpr int kSteps = 12;
    for (size_t t = 0; t < tris.size(); ++t) {
        const glm::dvec3 v0(tris[t].v0), v1(tris[t].v1), v2(tris[t].v2);
        for (int i = 0; i <= kSteps; ++i) {
            for (int j = 0; i + j <= kSteps; ++j) {
                const double u = double(i) / kSteps, v = double(j) / kSteps;
                const glm::dvec3 p = v0 + u * (v1 - v0) + v * (v2 - v0);
                uncovered += std::none_of(pieces[t].begin(), pieces[t].end(),
                                          [&](const BBox& b) { return contains_within_a_step(b, p); });
            }
        }
    }
    CHECK(uncovered == 0);
}

}  // namespace

TEST_CASE("split references lie inside their triangle's box and cover it", "[split-partitioning]") {
    SECTION("long slivers") {
        const std::vector<Triangle> tris = slivers_among_small_triangles(300, 3000, 1.0f, 1);
        const Partitioning p = partition_refs(tris, make_prim_refs(tris), 64, true);
        CHECK(p.reference_count() > tris.size() + 300);  // the slivers were split, most of them more than once
        check_split_references(tris, p);
    }
    SECTION("nearly degenerate triangles at extreme coordinates") {
        const std::vector<Triangle> tris = nearly_degenerate_and_extreme(2);
        const Partitioning p = partition_refs(tris, make_prim_refs(tris), 16, true);
        CHECK(p.reference_count() >= tris.size());
        check_split_references(tris, p);
    }
}

TEST_CASE("split partitioning grows its memory in place and moves partitions that outgrow it", "[split-partitioning]") {
    const std::vector<Triangle> tris = slivers_among_small_triangles(2000, 6000, 1e4f, 3);
    const uint32_t threshold = 128;
    const Partitioning p = partition_refs(tris, make_prim_refs(tris), threshold, true);
    const size_t refs = p.reference_count();
    CHECK(refs > tris.size() * 5 / 4);
    CHECK(p.regions.size() > 1);  // some right sides outgrew the free space and moved with 20% padding
    CHECK(p.reference_capacity >= refs);
    CHECK(p.reference_capacity < 3 * refs);
    // Partitions do not overlap in memory.
    std::vector<std::pair<const PrimRef*, const PrimRef*>> spans;
    for (const auto& part : p.partitions) spans.push_back({part.data(), part.data() + part.size()});
    std::sort(spans.begin(), spans.end());
    for (size_t i = 1; i < spans.size(); ++i) CHECK(spans[i - 1].second <= spans[i].first);
    const std::vector<PrimRef> compacted = compact(p);
    CHECK(compacted.size() == refs);
    check_split_references(tris, p);
}

TEST_CASE("mid-point partitioning without splits permutes the refs", "[split-partitioning]") {
    const std::vector<Triangle> tris = slivers_among_small_triangles(100, 5000, 1.0f, 4);
    const Partitioning p = partition_refs(tris, make_prim_refs(tris), 256, false);
    CHECK(p.reference_capacity == tris.size());
    std::vector<uint32_t> seen(tris.size(), 0);
    for (const auto& part : p.partitions) {
        CHECK(part.size() <= 256);
        for (const PrimRef& ref : part) ++seen[ref.prim];
    }
    CHECK(std::count(seen.begin(), seen.end(), 1u) == std::ptrdiff_t(tris.size()));
}

TEST_CASE("split partitioning is the same with 1 and 2 threads", "[split-partitioning]") {
    const std::vector<Triangle> tris = slivers_among_small_triangles(3000, 40000, 1.0f, 5);
    auto run = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        const Partitioning p = partition_refs(tris, make_prim_refs(tris), 512, true);
        return std::pair{compact(p), p.reference_capacity};
    };
    const auto [one, one_capacity] = run(1);
    const auto [two, two_capacity] = run(2);
    REQUIRE(one.size() == two.size());
    CHECK(std::memcmp(one.data(), two.data(), one.size() * sizeof(PrimRef)) == 0);
    CHECK(one_capacity == two_capacity);
}

TEST_CASE("the partition threshold follows sec. 3.2", "[split-partitioning]") {
    CHECK(split_partition_threshold(50'000) == 512);
    CHECK(split_partition_threshold(100'000) == 512);
    CHECK(split_partition_threshold(2'050'000) == 512 + (8192 - 512) / 2);
    CHECK(split_partition_threshold(4'000'000) == 8192);
    CHECK(split_partition_threshold(12'000'000) == 8192);
    const std::vector<Triangle> one{{Vec3(0), Vec3(1, 0, 0), Vec3(0, 1, 0)}};
    CHECK_THROWS_AS(partition_refs(one, make_prim_refs(one), 0, true), std::invalid_argument);
}
