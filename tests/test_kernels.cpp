// Kernel dispatch and the counting variant of traversal.
#include "oracle.h"

#include <bit>
#include <cstring>

using namespace canopy;
using namespace canopy::test;

TEST_CASE("kernel dispatch picks the widest kernel and names what is missing", "[kernels]") {
    const int widest = kernel_width("auto");
    for (const KernelInfo& k : kernel_infos())
        if (kernel_compiled(k.width) && cpu_runs(k.width)) CHECK(widest >= k.width);
    CHECK(kernel_width("bvh2") == 2);
    CHECK_THROWS_WITH(kernel_width("bvh3"), Catch::Contains("unknown kernel 'bvh3'"));
    for (const KernelInfo& k : kernel_infos())
        if (!kernel_compiled(k.width) || !cpu_runs(k.width)) CHECK_THROWS_WITH(kernel_width(k.name), Catch::Contains(k.isa));
}

template <int N>
void check_counts(const WideBvh<N>& bvh) {
    if constexpr (kernel_compiled(N)) {
        INFO("width " << N);
        TraversalCounts miss;
        Hit hit;
        CHECK(!traverse<Query::Closest>(bvh, Ray{{0, 0, 5}, {0, 0, 1}}, hit, miss));  // away from the root box
        CHECK(miss.inner_nodes == 1);
        CHECK(miss.leaf_nodes == 0);
        CHECK(miss.triangle_tests == 0);

        TraversalCounts counted;
        Hit counted_hit, plain_hit;
        const Ray down{{0.25f, 0.25f, 1.0f}, {0, 0, -1}};
        CHECK(traverse<Query::Closest>(bvh, down, counted_hit, counted));
        CHECK(closest_hit(bvh, down, plain_hit));
        CHECK(counted_hit.prim == plain_hit.prim);
        CHECK(counted.inner_nodes >= 1);
        CHECK(counted.leaf_nodes >= 1);
        CHECK(counted.triangle_tests >= counted.leaf_nodes);
    }
}

TEST_CASE("the counting variant counts visits and finds the same hits", "[kernels]") {
    // Two triangles in z = 0 and one far away: one leaf or more, counted per visit.
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},
                                     {Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)},
                                     {Vec3(-3, -3, -1), Vec3(-2, -3, -1), Vec3(-3, -2, -1)}};
    const BuiltScene built = build_with("binned", tris);
    check_counts(built.bvh2);
    check_counts(built.bvh4);
    check_counts(built.bvh8);

    const FlatScene flat = flatten(load_scene("gen:box?tris=5000&seed=2"));
    const BuiltScene box = build_with("binned", flat.triangles);
    TraversalCounts total;
    for (const Ray& ray : random_rays(flat.triangles, 1000, 3)) {
        Hit hit;
        traverse<Query::Closest>(box.bvh2, ray, hit, total);
    }
    CHECK(total.inner_nodes >= 1000);
    CHECK(total.triangle_tests >= total.leaf_nodes);
}

namespace {

// Whether the ray touches the box for some t in [tmin, tmax], in double precision: the float inputs' differences
// and quotients round at 2^-53 there, far below the float kernel's padding, so a touch it finds is a real one
// for the float kernel's purposes.
bool touches(const Ray& ray, const BBox& box) {
    double t0 = ray.tmin, t1 = ray.tmax;
    for (int a = 0; a < 3; ++a) {
        const double o = ray.org[a], d = ray.dir[a], lo = box.lower[a], hi = box.upper[a];
        if (d == 0.0) {
            if (o < lo || o > hi) return false;
            continue;
        }
        const double n = (lo - o) / d, f = (hi - o) / d;
        t0 = std::max(t0, std::min(n, f));
        t1 = std::min(t1, std::max(n, f));
    }
    return t0 <= t1;
}

// The node test of width N on a node whose first child is `box` and whose other children are empty, its planes
// in a frame at the box's centre, as collapse() stores a tree's.
// With `compressed`, the node's compressed form (bvh8), its frame's bound covering the decoded planes as compress()
// sets it.
template <int N>
bool node_test_hits(const BBox& box, const Ray& ray, bool robust, bool compressed = false) {
    PlaneFrame frame = PlaneFrame::centred(box);
    WideNode<N> node;
    for (int i = 0; i < N; ++i) {
        frame.set_box(node, i, i == 0 ? box : BBox{});
        node.child[i] = i == 0 ? 0 : WideNode<N>::kEmpty;
        node.count[i] = 0;
    }
    std::array<float, N> tnear;
    const float tmin = kernel_tmin(ray);
    if constexpr (N == 8) {
        if (compressed) {
            const CompressedNode<N> packed = compress_node(node);
            for (int a = 0; a < 3; ++a)
                frame.bound = std::max({frame.bound, std::abs(packed.lower(a, 0)), std::abs(packed.upper(a, 0))});
            const detail::NodeRay<N> lanes(detail::SlabRay<N>(ray, frame, robust));
            return detail::intersect_children<N>(packed, lanes, simd::Simd<N>::set1(tmin), ray.tmax, tnear) & 1;
        }
    }
    const detail::SlabRay<N> slab(ray, frame, robust);
    const detail::NodeRay<N> lanes(slab);
    if constexpr (N == 2) return detail::intersect_children<N>(node, lanes, tmin, ray.tmax, tnear) & 1;
    else return detail::intersect_children<N>(node, lanes, simd::Simd<N>::set1(tmin), ray.tmax, tnear) & 1;
}

// Boxes at offsets out to 1e30 and scales from 1e-30 to 1e30 (some flat), rays from afar or from near the coordinate
// origin aimed exactly at a corner, an edge or a face point, and rays with zero direction components whose origin
// lies in the box's slab, on its planes included. Returns {touching rays, those the node test culls}.
template <int N>
std::pair<size_t, size_t> culled_touching_rays(bool robust, bool compressed = false) {
    std::mt19937_64 rng(77);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    size_t touching = 0, culled = 0;
    // Past 1.8e19 an origin times a zero component's reciprocal (2^64) overflows: SlabRay disables that axis.
    for (const float offset : {0.0f, 1e3f, 1e5f, 1e7f, 1e20f, 1e30f})
        for (const float scale : {1e-30f, 1e-4f, 1.0f, 1e4f, 1e30f})
            for (int i = 0; i < 400; ++i) {
                BBox box;
                const Vec3 corner = Vec3(offset) + scale * Vec3(unit(rng), unit(rng), unit(rng));
                Vec3 size = scale * Vec3(unit(rng), unit(rng), unit(rng));
                if (i % 5 == 0) size[i % 3] = 0.0f;  // flat
                box.lower = corner, box.upper = corner + size;
                Vec3 target;
                for (int a = 0; a < 3; ++a) target[a] = unit(rng) < 0.6f ? (unit(rng) < 0.5f ? box.lower[a] : box.upper[a]) : glm::mix(box.lower[a], box.upper[a], unit(rng));
                const Vec3 away = glm::normalize(Vec3(unit(rng), unit(rng), unit(rng)) - 0.5f);
                // Every third ray starts near the coordinate origin, so that for far boxes its distance to the box
                // dwarfs its origin's magnitude: the padding must cover the rounding of the distance itself, not
                // only of the origin's terms.
                const Vec3 origin = i % 3 == 1 ? scale * (Vec3(unit(rng), unit(rng), unit(rng)) - 0.5f)
                                               : target + (10.0f + 1000.0f * unit(rng)) * scale * away;
                Ray ray{origin, glm::normalize(target - origin)};
                if (i % 7 == 0) {  // a zero component, the origin in that axis's slab (on a plane every other time)
                    const int a = i % 3;
                    ray.dir[a] = (i / 7) % 2 ? 0.0f : -0.0f;
                    ray.org[a] = (i / 7) % 4 < 2 ? box.lower[a] : glm::mix(box.lower[a], box.upper[a], 0.5f);
                    if (glm::dot(ray.dir, ray.dir) == 0.0f) ray.dir[(a + 1) % 3] = 1.0f;
                }
                if (!touches(ray, box)) continue;
                ++touching;
                culled += !node_test_hits<N>(box, ray, robust, compressed);
            }
    return {touching, culled};
}

}  // namespace

TEST_CASE("the robust node test never culls a box the ray touches, at any offset and scale", "[kernels][extreme]") {
    const auto check = [](auto width) {
        constexpr int N = decltype(width)::value;
        if constexpr (kernel_compiled(N)) {
            INFO("width " << N);
            const auto [touching, robust_culled] = culled_touching_rays<N>(true);
            CHECK(touching > 3000);
            CHECK(robust_culled == 0);
            // The set is adversarial: without the padding, rounding culls some of these boxes.
            CHECK(culled_touching_rays<N>(false).second > 0);
            if constexpr (N == 8) CHECK(culled_touching_rays<N>(true, true).second == 0);  // compressed nodes
        }
    };
    check(std::integral_constant<int, 2>{});
    check(std::integral_constant<int, 4>{});
    check(std::integral_constant<int, 8>{});
}

// The node test compares distances by their bits, which needs a start of +0 or more: every kernel takes a
// negative, -0 or NaN tmin as 0, so it finds what tmin = 0 finds, and no hit behind the origin.
TEST_CASE("a negative, negative-zero or NaN tmin counts as 0 in every kernel", "[kernels][extreme]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=16"));
    const BuiltScene built = build_with("binned", flat.triangles);
    const std::vector<Ray> rays = random_rays(flat.triangles, 2000, 43);
    size_t hits = 0;
    for (const KernelUnderTest& kernel : kernels_of(built))
        for (const float tmin :
             {-1.0f, -0.0f, -std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN()})
            for (Ray ray : rays) {
                const Hit from_zero = kernel.closest(ray);
                hits += from_zero.found();
                ray.tmin = tmin;
                const Hit hit = kernel.closest(ray);
                INFO(kernel.name << " tmin " << tmin);
                REQUIRE(hit.prim == from_zero.prim);
                REQUIRE((hit.t == from_zero.t || !hit.found()));
                REQUIRE(kernel.any(ray) == from_zero.found());
            }
    CHECK(hits > 1000);
}

// The kernels set the triangle test up at once for rays from inside the scene's box (BBox::contains) and at the
// first leaf for the others; the oracle tests above cover both kinds. The box test is inclusive and false on NaN.
TEST_CASE("BBox::contains is inclusive and false for NaN", "[kernels]") {
    const BBox box{{-1, -2, -3}, {1, 2, 3}};
    CHECK(box.contains({0, 0, 0}));
    CHECK(box.contains({-1, 2, 3}));
    CHECK_FALSE(box.contains({0, 2.5f, 0}));
    CHECK_FALSE(box.contains({0, 0, std::numeric_limits<float>::quiet_NaN()}));
    CHECK_FALSE(BBox{}.contains({0, 0, 0}));
}

template <int N, class TriangleTest>
void check_nearest_corners(const WideBvh<N>& bvh, std::span<const Triangle> tris, const std::vector<Ray>& rays) {
    if constexpr (kernel_compiled(N)) {
        if (!cpu_runs(N)) return;
        INFO("width " << N);
        size_t hits = 0;
        for (const Ray& ray : rays) {
            Hit plain, hit;
            NearestCorners<N> nearest;
            const bool found = traverse<Query::Closest, true, TriangleTest>(bvh, ray, hit, nearest);
            traverse<Query::Closest, true, TriangleTest>(bvh, ray, plain);
            REQUIRE(found == plain.found());
            REQUIRE(hit.prim == plain.prim);
            REQUIRE(std::bit_cast<uint32_t>(hit.t) == std::bit_cast<uint32_t>(plain.t));
            if (!found) continue;
            ++hits;
            const Triangle corners = nearest.triangle(), &scene = tris[hit.prim];
            REQUIRE(std::memcmp(&corners, &scene, sizeof(Triangle)) == 0);
        }
        CHECK(hits > rays.size() / 4);
    }
}

// The path tracer shades a hit with the corners the traversal kept (NearestCorners), not the scene's triangle:
// they must be that triangle's, bit for bit, for every width, intersector, and with ties between triangles.
TEST_CASE("the nearest hit's corners are its scene triangle's, bit for bit", "[kernels]") {
    for (const char* spec : {"gen:box?tris=3000&seed=4", "gen:cylinders?tris=2000&seed=6"}) {
        INFO(spec);
        const FlatScene flat = flatten(load_scene(spec));
        std::vector<Ray> rays = random_rays(flat.triangles, 4000, 13);
        const std::vector<Ray> corners = corner_and_edge_rays(flat.triangles, 2000, 1.0f);  // shared by triangles: ties
        rays.insert(rays.end(), corners.begin(), corners.end());
        const BuiltScene built = build_with("binned", flat.triangles);
        check_nearest_corners<2, WatertightRay>(built.bvh2, flat.triangles, rays);
        check_nearest_corners<4, WatertightRay>(built.bvh4, flat.triangles, rays);
        check_nearest_corners<8, WatertightRay>(built.bvh8, flat.triangles, rays);
        check_nearest_corners<8, MollerTrumboreRay>(built.bvh8, flat.triangles, rays);
    }
}
