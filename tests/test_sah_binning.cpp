// The object binning shared by binned and sbvh (accel/sah_binning.h): partitioning must send every reference to
// the side its bin was counted on, or the children's boxes miss references; and the sweep must find the split a
// plain evaluation of every bin plane finds, with that split's boxes and counts.
#include "accel/builder.h"
#include "accel/sah_binning.h"
#include "accel/builders/sbvh.h"

#include <catch2/catch.hpp>

#include <cfloat>
#include <cmath>
#include <random>
#include <vector>

using namespace canopy;
using namespace canopy::sah_binning;

namespace {

std::vector<PrimRef> random_refs(size_t n, float scale, float offset, std::mt19937& rng) {
    std::uniform_real_distribution<float> u(-1.0f, 1.0f), size(0.0f, 0.1f);
    std::vector<PrimRef> refs(n);
    for (size_t i = 0; i < n; ++i) {
        const Vec3 p(offset + scale * u(rng), offset + scale * u(rng), offset + scale * u(rng));
        refs[i].lower = p;
        refs[i].upper = p + scale * Vec3(size(rng), size(rng), size(rng));
        refs[i].prim = uint32_t(i);
    }
    return refs;
}

Box4 centroid_bounds(const std::vector<PrimRef>& refs) {
    Box4 b = Box4::empty();
    for (const PrimRef& r : refs) b.extend(center2(r));
    return b;
}

int bin_of(const BinMapping& mapping, const PrimRef& r, int axis) {
    alignas(16) int32_t b[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(b), mapping.bin3(center2(r)));
    return b[axis];
}

void check_planes_agree_with_bins(const std::vector<PrimRef>& refs, uint32_t bins) {
    const BinMapping mapping(centroid_bounds(refs), bins);
    for (int axis = 0; axis < 3; ++axis)
        for (uint32_t k = 1; k < bins; ++k) {
            const BinMapping::Plane plane = mapping.plane(axis, k);
            for (const PrimRef& r : refs) REQUIRE(plane.left_of(r) == (bin_of(mapping, r, axis) < int(k)));
        }
}

}  // namespace

TEST_CASE("A bin plane sends every reference to the side its bin is on, at every scale", "[sah_binning]") {
    std::mt19937 rng(7);
    for (float scale : {1e-38f, 1e-20f, 1e-3f, 1.0f, 1e6f, 1e30f, 1e38f})
        for (float offset : {0.0f, 1.0f, -1e6f, 3e38f})
            for (uint32_t bins : {4u, 7u, 32u}) check_planes_agree_with_bins(random_refs(64, scale, offset, rng), bins);
}

TEST_CASE("A bin plane agrees with the bins where the bin position is NaN or infinite", "[sah_binning]") {
    auto point_ref = [](float x, float y, float z) {
        PrimRef r;
        r.lower = r.upper = Vec3(x, y, z);
        return r;
    };
    const float tiny = std::numeric_limits<float>::denorm_min();
    // Centroid extents of a few denormals: bins / extent overflows to inf, and 0 * inf is NaN.
    check_planes_agree_with_bins({point_ref(0, 0, 0), point_ref(tiny, 2 * tiny, 0), point_ref(3 * tiny, tiny, 0)}, 32);
    // Doubled centroids overflow to inf next to finite ones: the extent is inf and inf * 0 is NaN.
    check_planes_agree_with_bins({point_ref(FLT_MAX, 1, FLT_MAX), point_ref(0, 2, -FLT_MAX), point_ref(1e38f, 3, 0)}, 32);
    // Only overflowed centroids: the extent is inf - inf.
    check_planes_agree_with_bins({point_ref(FLT_MAX, FLT_MAX, FLT_MAX), point_ref(FLT_MAX, FLT_MAX, FLT_MAX)}, 4);
}

TEST_CASE("The sweep finds the best bin plane, with its boxes and counts", "[sah_binning]") {
    std::mt19937 rng(11);
    for (size_t n : {size_t(2), size_t(9), size_t(300), size_t(40000)})  // 40000: binned in parallel chunks
        for (uint32_t block : {1u, 2u, 4u}) {
            const std::vector<PrimRef> refs = random_refs(n, 1.0f, 0.0f, rng);
            BuildSettings settings;
            settings.leaf_block = block;
            const BinMapping mapping(centroid_bounds(refs), std::min<uint32_t>(kMaxBins, std::max<uint32_t>(uint32_t(n), 4)));
            const Split split = best_split(bin_refs(refs.data(), 0, uint32_t(n), mapping), mapping.bins, settings);

            // Every plane evaluated from the references themselves.
            Split expected;
            for (int axis = 0; axis < 3; ++axis)
                for (uint32_t k = 1; k < mapping.bins; ++k) {
                    Box4 left = Box4::empty(), right = Box4::empty();
                    uint32_t nl = 0, nr = 0;
                    for (const PrimRef& r : refs) {
                        const bool goes_left = bin_of(mapping, r, axis) < int(k);
                        (goes_left ? left : right).extend(Box4::of(r));
                        ++(goes_left ? nl : nr);
                    }
                    if (nl == 0 || nr == 0) continue;
                    const float cost = left.half_area() * settings.leaf_tests(nl) + right.half_area() * settings.leaf_tests(nr);
                    if (cost < expected.cost) expected = {axis, k, cost, left, right, nl, nr};
                }
            INFO("n " << n << ", block " << block);
            REQUIRE(split.axis == expected.axis);
            REQUIRE(split.bin == expected.bin);
            REQUIRE(split.cost == expected.cost);
            REQUIRE(split.left_count == expected.left_count);
            REQUIRE(split.right_count == expected.right_count);
            const BBox l = split.left.bbox(), el = expected.left.bbox(), r = split.right.bbox(), er = expected.right.bbox();
            REQUIRE((l.lower == el.lower && l.upper == el.upper && r.lower == er.lower && r.upper == er.upper));
        }
}

TEST_CASE("The builders that sweep bins refuse a leaf block that is not a power of two", "[sah_binning]") {
    std::mt19937 rng(3);
    const std::vector<PrimRef> refs = random_refs(16, 1.0f, 0.0f, rng);
    std::vector<Triangle> triangles(refs.size());
    for (size_t i = 0; i < refs.size(); ++i) triangles[i] = {refs[i].lower, refs[i].upper, refs[i].lower + Vec3(0, 1, 0)};
    BuildSettings settings;
    settings.leaf_block = 3;
    REQUIRE_THROWS_AS(find_builder("binned").build(BuildInput{triangles, refs}, settings), std::invalid_argument);
    SbvhSettings sbvh;  // sbvh prices leaves by its own block, whatever the kernel's
    sbvh.leaf_block = 3;
    REQUIRE_THROWS_AS(build_sbvh_with(BuildInput{triangles, refs}, BuildSettings{}, sbvh), std::invalid_argument);
    sbvh.leaf_block = 2;
    REQUIRE_NOTHROW(build_sbvh_with(BuildInput{triangles, refs}, settings, sbvh));
}
