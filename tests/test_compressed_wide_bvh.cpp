// Compressed wide nodes (accel/compressed_wide_bvh.h): quantised planes never shrink a box and decode exactly, at
// every magnitude; the compressed kernel's answers are the standard kernel's, bit for bit.
#include "accel/compressed_wide_bvh.h"
#include "accel/metrics.h"
#include "oracle.h"

#include <bit>
#include <cmath>
#include <cstring>

using namespace canopy;
using namespace canopy::test;

namespace {

// The plane as the kernel decodes it (one FMA) equals the exact value origin + q 2^e, computed in double.
void check_decodes_exactly(float origin, float scale, uint8_t q) {
    const double exact = double(origin) + double(q) * double(scale);
    REQUIRE(double(std::fma(float(q), scale, origin)) == exact);
}

// Boxes at offsets out to 1e30 and sizes from 1e-30 to 1e30, some flat, some single points.
std::vector<BBox> extreme_boxes(size_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const float offsets[] = {0.0f, 1e-30f, 1.0f, 1e7f, -1e7f, 1e20f, -1e30f};
    const float sizes[] = {0.0f, 1e-30f, 1e-7f, 1.0f, 1e4f, 1e20f, 1e30f};
    std::vector<BBox> boxes;
    for (size_t i = 0; i < count; ++i) {
        const float offset = offsets[rng() % std::size(offsets)], size = sizes[rng() % std::size(sizes)];
        const Vec3 lower = Vec3(offset) + size * Vec3(unit(rng), unit(rng), unit(rng)) * (unit(rng) < 0.5f ? -1.0f : 1.0f);
        Vec3 extent = size * Vec3(unit(rng), unit(rng), unit(rng));
        if (i % 5 == 0) extent[i % 3] = 0.0f;
        boxes.push_back({lower, lower + extent});
    }
    return boxes;
}

}  // namespace

TEST_CASE("quantised planes contain the exact ones, decode exactly and lose at most a step", "[compressed][extreme]") {
    const std::vector<BBox> boxes = extreme_boxes(8000, 5);
    size_t nodes = 0;
    for (size_t first = 0; first + 8 <= boxes.size(); first += 8) {
        // A node of 1 to 8 children, the others empty, as collapse() leaves them.
        const int children = 1 + int(first / 8 % 8);
        WideNode<8> node;
        const PlaneFrame frame{Vec3(0.0f), 0.0f};
        for (int i = 0; i < 8; ++i) {
            frame.set_box(node, i, i < children ? boxes[first + i] : BBox{});
            node.child[i] = i < children ? uint32_t(i) : WideNode<8>::kEmpty;
            node.count[i] = i < children ? uint32_t(i % 2 * 3) : 0;
        }
        const CompressedNode<8> packed = compress_node(node);
        ++nodes;
        for (int i = 0; i < 8; ++i) {
            REQUIRE(packed.is_empty(i) == node.is_empty(i));
            REQUIRE(packed.child[i] == node.child[i]);
            if (node.is_empty(i)) {
                for (int a = 0; a < 3; ++a) CHECK(packed.lower(a, i) > packed.upper(a, i));  // an inverted box
                continue;
            }
            REQUIRE(packed.count[i] == node.count[i]);
            for (int a = 0; a < 3; ++a) {
                INFO("node " << nodes << " child " << i << " axis " << a << ": [" << node.lower(a, i) << ", "
                              << node.upper(a, i) << "] origin " << packed.origin[a] << " scale " << packed.scale[a]);
                check_decodes_exactly(packed.origin[a], packed.scale[a], packed.q[a * 8 + i]);
                check_decodes_exactly(packed.origin[a], packed.scale[a], packed.q[(3 + a) * 8 + i]);
                REQUIRE(packed.lower(a, i) <= node.lower(a, i));
                REQUIRE(packed.upper(a, i) >= node.upper(a, i));
                // Rounded to the step below and above, not further: the node box spans at most 255 steps.
                REQUIRE(double(packed.lower(a, i)) + double(packed.scale[a]) > double(node.lower(a, i)));
                REQUIRE(double(packed.upper(a, i)) - double(packed.scale[a]) < double(node.upper(a, i)));
            }
        }
    }
    CHECK(nodes == 1000);
}

TEST_CASE("compression refuses what its bytes cannot hold", "[compressed]") {
    WideNode<8> node;
    const PlaneFrame frame{Vec3(0.0f), 0.0f};
    for (int i = 0; i < 8; ++i) {
        frame.set_box(node, i, i == 0 ? BBox{Vec3(0.0f), Vec3(1.0f)} : BBox{});
        node.child[i] = i == 0 ? 0 : WideNode<8>::kEmpty;
        node.count[i] = i == 0 ? 70000 : 0;
    }
    CHECK_THROWS_AS(compress_node(node), std::length_error);
    // Planes whose rounding up would pass the largest float.
    CHECK_THROWS_AS(quantise_axis(-3.4e38f, 3.4e38f), std::range_error);
    CHECK_NOTHROW(quantise_axis(-1e38f, 1e38f));
}

namespace {

template <bool Robust, class TriangleTest>
void check_same_answers(const WideBvh<8>& standard, const CompressedWideBvh<8>& compressed,
                        std::span<const Triangle> tris, const std::vector<Ray>& rays) {
    size_t hits = 0, corner_mismatches = 0, ties = 0;
    TraversalCounts standard_counts, compressed_counts;
    INFO((Robust ? "robust" : "fast") << " traversal, " << (std::is_same_v<TriangleTest, WatertightRay> ? "watertight" : "Möller–Trumbore"));
    for (const Ray& ray : rays) {
        Hit expected, actual;
        NearestCorners<8> nearest;
        traverse<Query::Closest, Robust, TriangleTest>(standard, ray, expected, standard_counts);
        traverse<Query::Closest, Robust, TriangleTest>(compressed, ray, actual, nearest);
        traverse<Query::Closest, Robust, TriangleTest>(compressed, ray, actual, compressed_counts);
        REQUIRE(actual.found() == expected.found());
        REQUIRE(any_hit<Robust, TriangleTest>(compressed, ray) == expected.found());
        if (!expected.found()) continue;
        ++hits;
        REQUIRE(std::bit_cast<uint32_t>(actual.t) == std::bit_cast<uint32_t>(expected.t));
        if (actual.prim == expected.prim) {
            REQUIRE(std::bit_cast<uint32_t>(actual.u) == std::bit_cast<uint32_t>(expected.u));
            REQUIRE(std::bit_cast<uint32_t>(actual.v) == std::bit_cast<uint32_t>(expected.v));
        } else {  // a tie, which the order of visits decides: the other triangle alone is hit at the same distance
            const Triangle& t = tris[actual.prim];
            Hit alone;
            alone.t = ray.tmax;
            REQUIRE(TriangleTest(ray).intersect(t.v0, t.v1, t.v2, actual.prim, kernel_tmin(ray), alone));
            REQUIRE(std::bit_cast<uint32_t>(alone.t) == std::bit_cast<uint32_t>(expected.t));
            ++ties;
        }
        const Triangle corners = nearest.triangle();
        corner_mismatches += std::memcmp(&corners, &tris[actual.prim], sizeof(Triangle)) != 0;
    }
    CHECK(hits > rays.size() / 4);
    CHECK(ties < hits / 100);
    CHECK(corner_mismatches == 0);
    // Boxes a step larger: at least the standard tree's visits, over half the lines.
    CHECK(compressed_counts.inner_nodes >= standard_counts.inner_nodes);
    CHECK(compressed_counts.cache_lines < standard_counts.cache_lines);
}

}  // namespace

TEST_CASE("the compressed bvh8 kernel answers as the standard one, bit for bit, and as brute force", "[compressed]") {
    if constexpr (kernel_compiled(8)) {
        if (!cpu_runs(8)) return;
        for (const float scale : {1.0f, 1e-12f, 1e12f})
            for (const char* spec : {"gen:box?tris=3000&seed=4", "gen:cylinders?tris=2000&seed=6"}) {
                INFO(spec << " scaled by " << scale << ", a thousand times its size from the origin");
                const std::vector<Triangle> tris = scaled_far_from_origin(flatten(load_scene(spec)).triangles, scale);
                std::vector<Ray> rays = random_rays(tris, 3000, 13);
                const std::vector<Ray> corners = corner_and_edge_rays(tris, 1000, scale);
                rays.insert(rays.end(), corners.begin(), corners.end());
                const BuiltScene built = build_with("binned", tris);
                WideBvh<8> copy = built.bvh8;
                const CompressedWideBvh<8> compressed = compress(std::move(copy));
                check_same_answers<true, WatertightRay>(built.bvh8, compressed, tris, rays);
                check_same_answers<true, MollerTrumboreRay>(built.bvh8, compressed, tris, rays);
                // Against brute force. The fast traversal's rounding may cull a box a ray grazes, more so this far
                // from the origin: it may lose a ray in 10,000 (test_oracle.cpp) beyond what the standard one loses.
                const std::vector<Hit> expected = brute_force_all(tris, rays);
                std::vector<Hit> robust(rays.size()), fast(rays.size()), standard_fast(rays.size());
                for (size_t i = 0; i < rays.size(); ++i) {
                    closest_hit(compressed, rays[i], robust[i]);
                    closest_hit<false>(compressed, rays[i], fast[i]);
                    closest_hit<false>(built.bvh8, rays[i], standard_fast[i]);
                }
                CHECK(count_mismatches(rays, expected, robust, "compressed bvh8") == 0);
                CHECK(count_mismatches(rays, expected, fast, "compressed bvh8, fast") <=
                      count_mismatches(rays, expected, standard_fast, "bvh8, fast") + std::max<size_t>(1, rays.size() / 10000));
                // Half the node bytes, the same leaves.
                CHECK(compressed.bytes() == built.bvh8.bytes() - built.bvh8.nodes.size() * 128);
            }
    }
}

TEST_CASE("decompressed nodes hold the decoded boxes, which contain the collapse's", "[compressed]") {
    if constexpr (kernel_compiled(8)) {
        const std::vector<Triangle> tris = flatten(load_scene("gen:box?tris=2000&seed=8")).triangles;
        const BuiltScene built = build_with("sweep", tris);
        WideBvh<8> copy = built.bvh8;
        const WideBvh<8> back = decompress(compress(std::move(copy)));
        REQUIRE(back.nodes.size() == built.bvh8.nodes.size());
        REQUIRE(back.leaves.size() == built.bvh8.leaves.size());
        for (size_t n = 0; n < back.nodes.size(); ++n)
            for (int i = 0; i < 8; ++i) {
                const WideNode<8>&a = built.bvh8.nodes[n], &b = back.nodes[n];
                REQUIRE(a.child[i] == b.child[i]);
                REQUIRE(a.count[i] == b.count[i]);
                if (a.is_empty(i)) continue;
                for (int axis = 0; axis < 3; ++axis) {
                    REQUIRE(b.lower(axis, i) <= a.lower(axis, i));
                    REQUIRE(b.upper(axis, i) >= a.upper(axis, i));
                }
            }
        CHECK(sah_cost(back) >= sah_cost(built.bvh8));
    }
}
