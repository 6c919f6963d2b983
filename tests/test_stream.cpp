// Batch queries (kernels/traverse_stream.h), ray ordering (kernels/ray_order.h) and the wavefront path tracer
// (renderer/wavefront.h): every batch answer is the single-ray kernel's, and the stream tracer renders the same
// paths as the single-path tracer.
#include "kernels/ray_order.h"
#include "experiments/embree_accelerator.h"
#include "kernels/traverse_stream.h"
#include "oracle.h"
#include "renderer/frames.h"
#include "renderer/wavefront.h"
#include "test_scale.h"
#include "two_level_support.h"

#include <algorithm>
#include <bit>
#include <numeric>

using namespace canopy;
using namespace canopy::test;

namespace {

// Random rays plus the awkward ones: every octant with zero and negative-zero components, bounded and
// backwards intervals, NaN and negative tmin, and origins inside the scene's boxes.
std::vector<Ray> adversarial_rays(std::span<const Triangle> tris, size_t random_count, uint64_t seed) {
    std::vector<Ray> rays = random_rays(tris, random_count, seed);
    BBox bounds;
    for (const Triangle& t : tris) bounds.extend(BBox::of(t));
    const Vec3 c = bounds.center();
    const float components[] = {1.0f, -1.0f, 0.0f, -0.0f, 0.3f, -0.3f};
    for (float x : components)
        for (float y : components)
            for (float z : components) {
                if (x == 0.0f && y == 0.0f && z == 0.0f) continue;
                rays.push_back({c, {x, y, z}});
                rays.push_back({bounds.lower - Vec3(0.01f), {x, y, z}, 0.0f, 0.5f * glm::length(bounds.extent())});
            }
    std::mt19937 rng{uint32_t(seed)};
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (size_t i = 0; i < rays.size(); i += 5) {
        Ray& r = rays[i];
        const float reach = glm::length(bounds.extent());
        switch (i / 5 % 4) {
            case 0: r.tmin = unit(rng) * reach, r.tmax = r.tmin + unit(rng) * reach; break;
            case 1: r.tmin = -1.0f; break;
            case 2: r.tmin = std::numeric_limits<float>::quiet_NaN(); break;
            default: r.tmin = 2.0f, r.tmax = 1.0f;  // an empty interval: no hit
        }
    }
    return rays;
}

// Rays as the wavefront tracer hands them to a batch query: in RayOrderKey order, so rays of one octant and nearby
// origins form full packets, whose leaves test a triangle against every lane at once.
std::vector<Ray> in_key_order(std::span<const Triangle> tris, std::vector<Ray> rays) {
    BBox bounds;
    for (const Triangle& t : tris) bounds.extend(BBox::of(t));
    const RayOrderKey key(bounds);
    std::stable_sort(rays.begin(), rays.end(), [&](const Ray& a, const Ray& b) { return key(a) < key(b); });
    return rays;
}

// Bundles of nearly parallel rays of one octant from points around the scene, so every packet's rays share their
// watertight axes (the packet leaf test's uniform case), each bundle's direction dominated by another axis and sign.
std::vector<Ray> parallel_bundles(std::span<const Triangle> tris, uint64_t seed) {
    BBox bounds;
    for (const Triangle& t : tris) bounds.extend(BBox::of(t));
    std::mt19937 rng{uint32_t(seed)};
    std::uniform_real_distribution<float> spread(0.01f, 0.05f), unit(0.0f, 1.0f);
    std::vector<Ray> rays;
    for (int axis = 0; axis < 3; ++axis)
        for (float sign : {1.0f, -1.0f})
            for (int bundle = 0; bundle < 8; ++bundle) {
                Vec3 dir(0.0f), side;
                dir[axis] = sign;
                for (int a = 0; a < 3; ++a) side[a] = unit(rng) < 0.5f ? -1.0f : 1.0f;
                const Vec3 from = bounds.lower + Vec3(unit(rng), unit(rng), unit(rng)) * bounds.extent() - 0.6f * dir * bounds.extent();
                for (int r = 0; r < 64; ++r) {
                    Vec3 d = dir;
                    for (int a = 0; a < 3; ++a)
                        if (a != axis) d[a] = side[a] * spread(rng);
                    rays.push_back({from + 0.01f * Vec3(unit(rng), unit(rng), unit(rng)) * bounds.extent(), d});
                }
            }
    return rays;
}

bool same_bits(const Hit& a, const Hit& b) {
    return a.prim == b.prim && std::bit_cast<uint32_t>(a.t) == std::bit_cast<uint32_t>(b.t) &&
           std::bit_cast<uint32_t>(a.u) == std::bit_cast<uint32_t>(b.u) && std::bit_cast<uint32_t>(a.v) == std::bit_cast<uint32_t>(b.v);
}

// Whether `hit` is a closest hit of `ray`: brute force finds a hit at exactly its distance on its triangle.
template <class TriangleTest>
bool ties_at(std::span<const Triangle> tris, const Ray& ray, const Hit& hit) {
    const Triangle& t = tris[hit.prim];
    Hit alone;
    alone.t = ray.tmax;
    TriangleTest(ray).intersect(t.v0, t.v1, t.v2, hit.prim, kernel_tmin(ray), alone);
    return alone.found() && alone.t == hit.t;
}

// The batch query against the single-ray kernel, ray by ray: bit for bit in the single-ray mode; in the stream mode
// bit for bit but where two triangles tie exactly, when the stream's triangle must hit at the same distance. That
// holds for robust watertight kernels, whose answer does not depend on the order nodes are visited in. The fast
// modes' answers do: unpadded slabs may cull the box of a hit whose distance rounds past the running far limit,
// and Möller–Trumbore may hit outside a triangle's box, so which of two near hits is found depends on which leaf
// came first; the stream may then differ from the single-ray kernel on a few rays in a thousand.
template <Query Q, bool Robust, class TriangleTest, class Layout>
void check_batch(const Layout& bvh, std::span<const Triangle> tris, const std::vector<Ray>& rays, const std::string& what) {
    std::vector<Hit> single(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) traverse<Q, Robust, TriangleTest>(bvh, rays[i], single[i]);
    StreamScratch<Layout::kWidth> scratch;
    for (BatchTraversal how : {BatchTraversal::Single, BatchTraversal::Packet, BatchTraversal::Stream}) {
        std::vector<Hit> batch(rays.size());
        traverse_batch<Q, Robust, TriangleTest>(bvh, std::span<const Ray>(rays), std::span<Hit>(batch), scratch, how);
        size_t differ = 0, ties = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            const bool agree = Q == Query::Any ? batch[i].found() == single[i].found() : same_bits(batch[i], single[i]);
            if (agree) continue;
            const bool tie = how != BatchTraversal::Single && Q == Query::Closest && batch[i].found() && single[i].found() &&
                             batch[i].t == single[i].t && ties_at<TriangleTest>(tris, rays[i], batch[i]);
            (tie ? ties : differ) += 1;
            if (!tie && differ <= 3)
                UNSCOPED_INFO(what << (how == BatchTraversal::Stream ? " stream" : how == BatchTraversal::Packet ? " packet" : " single") << ": ray " << i << " single prim "
                                   << single[i].prim << " t " << single[i].t << ", batch prim " << batch[i].prim << " t " << batch[i].t);
        }
        INFO(what << ": " << ties << " exact ties");
        const bool order_free = Robust && std::is_same_v<TriangleTest, WatertightRay>;
        CHECK(differ <= (order_free || how == BatchTraversal::Single ? 0 : rays.size() / 500));
    }
}

template <bool Robust, class TriangleTest, class Layout>
void check_both_queries(const Layout& bvh, std::span<const Triangle> tris, const std::vector<Ray>& rays, const std::string& what) {
    if constexpr (kernel_compiled(Layout::kWidth)) {
        if (!cpu_runs(Layout::kWidth)) return;
        check_batch<Query::Closest, Robust, TriangleTest>(bvh, tris, rays, what + " closest");
        check_batch<Query::Any, Robust, TriangleTest>(bvh, tris, rays, what + " any");
    }
}

template <bool Robust, class TriangleTest>
void check_every_width(const BuiltScene& built, std::span<const Triangle> tris, const std::vector<Ray>& rays, const std::string& what) {
    if (built.has_bvh2) check_both_queries<Robust, TriangleTest>(built.bvh2, tris, rays, what + " bvh2");
    check_both_queries<Robust, TriangleTest>(built.bvh4, tris, rays, what + " bvh4");
    check_both_queries<Robust, TriangleTest>(built.bvh8, tris, rays, what + " bvh8");
}

}  // namespace

TEST_CASE("batch queries answer every ray as the single-ray kernel does, in every width and mode", "[stream]") {
    for (const char* spec : {"gen:box?tris=3000&seed=7", "gen:cylinders?tris=2000&seed=3"}) {
        const FlatScene flat = flatten(load_scene(spec));
        std::vector<Ray> rays = adversarial_rays(flat.triangles, scaled(6000, 1000), 11);
        const std::vector<Ray> sorted = in_key_order(flat.triangles, rays);
        rays.insert(rays.end(), sorted.begin(), sorted.end());
        const std::vector<Ray> bundles = parallel_bundles(flat.triangles, 4);
        rays.insert(rays.end(), bundles.begin(), bundles.end());
        for (const std::string builder : {"binned", "lbvh", "sbvh", "lbvh direct"}) {
            const BuiltScene built = builder == "lbvh direct" ? build_direct(flat.triangles) : build_with(builder, flat.triangles);
            const std::string what = spec + (" / " + builder);
            check_every_width<true, WatertightRay>(built, flat.triangles, rays, what + " robust watertight");
            check_every_width<false, WatertightRay>(built, flat.triangles, rays, what + " fast watertight");
            check_every_width<true, MollerTrumboreRay>(built, flat.triangles, rays, what + " robust moller");
            check_every_width<false, MollerTrumboreRay>(built, flat.triangles, rays, what + " fast moller");
        }
    }
}

// The batch paths translate ray origins into the tree's PlaneFrame as the single-ray kernel does, bit for bit.
TEST_CASE("batch queries far from the origin answer every ray as the single-ray kernel does", "[stream]") {
    const Vec3 far(1e7f, -1e9f, 3e11f);
    FlatScene flat = flatten(load_scene("gen:box?tris=3000&seed=5"));
    for (Triangle& t : flat.triangles) t = {t.v0 + far, t.v1 + far, t.v2 + far};
    const std::vector<Ray> rays = adversarial_rays(flat.triangles, scaled(6000, 1000), 12);
    const BuiltScene built = build_with("binned", flat.triangles);
    check_every_width<true, WatertightRay>(built, flat.triangles, rays, "moved box robust watertight");
    check_every_width<false, MollerTrumboreRay>(built, flat.triangles, rays, "moved box fast moller");
}

TEST_CASE("batch queries agree with brute force", "[stream]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=2000&seed=9"));
    const std::vector<Ray> rays = random_rays(flat.triangles, 4000, 5);
    const std::vector<Hit> expected = brute_force_all(flat.triangles, rays);
    const BuiltScene built = build_with("binned", flat.triangles);
    const auto check = [&](const auto& bvh, const char* name) {
        if constexpr (kernel_compiled(std::decay_t<decltype(bvh)>::kWidth)) {
            StreamScratch<std::decay_t<decltype(bvh)>::kWidth> scratch;
            for (BatchTraversal how : {BatchTraversal::Single, BatchTraversal::Packet, BatchTraversal::Stream}) {
                std::vector<Hit> batch(rays.size());
                traverse_batch<Query::Closest>(bvh, std::span<const Ray>(rays), std::span<Hit>(batch), scratch, how);
                CHECK(count_mismatches(rays, expected, batch, name) == 0);
            }
        }
    };
    check(built.bvh2, "bvh2");
    check(built.bvh4, "bvh4");
    check(built.bvh8, "bvh8");
}

TEST_CASE("batches of 0, 1, 7, 9 and a million rays", "[stream]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=1000&seed=2"));
    const BuiltScene built = build_with("binned", flat.triangles);
    const std::vector<Ray> million = random_rays(flat.triangles, 1'000'000, 8);
    for (size_t n : {size_t(0), size_t(1), size_t(7), size_t(9), size_t(kMinStreamRays) - 1u, size_t(kStreamChunk) + 1u}) {
        const std::vector<Ray> rays(million.begin(), million.begin() + ptrdiff_t(n));
        check_every_width<true, WatertightRay>(built, flat.triangles, rays, std::to_string(n) + " rays");
    }
    if constexpr (kernel_compiled(8)) {
        if (cpu_runs(8)) check_both_queries<true, WatertightRay>(built.bvh8, flat.triangles, million, "a million rays bvh8");
    }
}

TEST_CASE("batch queries over two-level and re-braided trees answer as the single-ray kernel", "[stream]") {
    const Scene scene = instanced_scene();
    const FlatScene flat = flatten(scene);
    const TwoLevelInput input = two_level_input(scene);
    const std::vector<Ray> rays = adversarial_rays(flat.triangles, 3000, 4);
    for (TopLevel top : {TopLevel::TwoLevel, TopLevel::Rebraid}) {
        TwoLevelSettings settings;
        settings.top = top;
        const std::string what = top == TopLevel::Rebraid ? "rebraid" : "two-level";
        check_both_queries<true, WatertightRay>(build_two_level<2>(input, settings), flat.triangles, rays, what + " bvh2");
        if constexpr (kernel_compiled(8)) {
            settings.blas.leaf_block = 4;
            check_both_queries<true, WatertightRay>(build_two_level<8>(input, settings), flat.triangles, rays, what + " bvh8");
            check_both_queries<false, MollerTrumboreRay>(build_two_level<8>(input, settings), flat.triangles, rays, what + " bvh8 fast moller");
        }
    }
}

TEST_CASE("rays are ordered by octant, then by origin cell, stably", "[stream]") {
    const BBox bounds{Vec3(-1.0f), Vec3(1.0f)};
    const RayOrderKey key(bounds);
    CHECK(key({{0, 0, 0}, {1, 1, 1}}) >> 27 == 0u);
    CHECK(key({{0, 0, 0}, {-1, 1, 1}}) >> 27 == 1u);
    CHECK(key({{0, 0, 0}, {1, 1, -1}}) >> 27 == 4u);
    CHECK(key({{0, 0, 0}, {-1, -1, -1}}) >> 27 == 7u);
    CHECK(key({{0, 0, 0}, {-0.0f, 1, 1}}) >> 27 == 0u);  // -0 is not negative: the kernels treat it as +0's axis
    // Origins outside the box, infinite and NaN ones fall into its edge cells instead of overflowing the key.
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    CHECK(key({{-5, -5, -5}, {1, 1, 1}}) == 0u);
    CHECK(key({{inf, inf, inf}, {1, 1, 1}}) == (1u << 27) - 1u);
    CHECK(key({{nan, nan, nan}, {1, 1, 1}}) == 0u);
    CHECK(RayOrderKey(BBox{Vec3(1.0f), Vec3(1.0f)})({{1, 1, 1}, {1, 1, 1}}) == 0u);  // a flat box

    std::mt19937 rng(3);
    std::vector<uint32_t> keys(100'000), order, scratch;
    for (uint32_t& k : keys) k = rng() & ((1u << RayOrderKey::kBits) - 1u) & 0x3ff0ffffu;  // many equal keys
    radix_order(keys, order, scratch);
    std::vector<uint32_t> expected(keys.size());
    std::iota(expected.begin(), expected.end(), 0u);
    std::stable_sort(expected.begin(), expected.end(), [&](uint32_t a, uint32_t b) { return keys[a] < keys[b]; });
    CHECK(order == expected);
    radix_order(std::span<const uint32_t>(), order, scratch);
    CHECK(order.empty());
}

namespace {

struct Frame {
    std::vector<float> pixels;
    double mean;
    uint64_t rays;
};

// Frames 3, 4, ... (`frames` of them) through one ShadingScene, so that the stream tracer's choices carry over.
Frame render_with(const Accelerator& accel, const Scene& scene, const FlatScene& flat, TracerKind tracer, uint32_t paths,
                  BatchTraversal how = BatchTraversal::Packet, StreamBatching batching = StreamBatching::Measured,
                  int frames = 1) {
    FrameSettings settings;
    settings.width = 48, settings.height = 36;
    settings.tracer = tracer, settings.stream_paths = paths, settings.batch_traversal = how;
    settings.stream_batching = batching;
    StreamStats stats;
    const ShadingScene shading{flat, settings, &stats};
    Image image(settings.width, settings.height);
    const PinholeCamera camera(scene_camera(scene, flat), settings.width, settings.height);
    uint64_t rays = 0;
    for (int f = 0; f < frames; ++f) rays += render(accel, shading, camera, uint32_t(3 + f), image);
    if (tracer == TracerKind::Stream) {
        CHECK(stats.batches.load() >= uint64_t(frames));
        CHECK((batching == StreamBatching::Paths) == (stats.path_batches.load() == stats.batches.load()));
        if (batching != StreamBatching::Paths) CHECK(stats.bytes.load() > 0);
    }
    return {image.average(frames), image.mean(frames), rays};
}

}  // namespace

TEST_CASE("the stream tracer renders the single-path tracer's paths", "[stream]") {
    for (const char* spec : {"gen:box?tris=3000&seed=1", "gen:surface?tris=2000&seed=2"}) {
        const Scene scene = load_scene(spec);
        const FlatScene flat = flatten(scene);
        for (const char* kernel : {"bvh2", "auto"}) {
            CanopyOptions options;
            options.kernel = kernel;
            auto accel = make_canopy_accelerator(scene, flat, options);
            accel->prepare();
            accel->build();
            const Frame single = render_with(*accel, scene, flat, TracerKind::Single, 0);
            // Batches that split the image unevenly, a path each, and a frame of fewer paths than one batch.
            for (uint32_t paths : {1u, 97u, 1u << 16})
                for (BatchTraversal how : {BatchTraversal::Packet, BatchTraversal::Single}) {
                    INFO(spec << " " << kernel << ", " << paths << " paths a batch, " << batch_traversal_name(how));
                    const Frame stream = render_with(*accel, scene, flat, TracerKind::Stream, paths, how);
                    CHECK(stream.rays == single.rays);
                    CHECK(stream.pixels == single.pixels);
                }
            // Each batch as a wavefront, path by path, or as measured, over frames whose choices carry over.
            const Frame singles = render_with(*accel, scene, flat, TracerKind::Single, 0, BatchTraversal::Packet,
                                              StreamBatching::Measured, 3);
            for (StreamBatching batching : {StreamBatching::Wavefront, StreamBatching::Paths, StreamBatching::Measured}) {
                INFO(spec << " " << kernel << ", batches " << stream_batching_name(batching));
                const Frame stream = render_with(*accel, scene, flat, TracerKind::Stream, 97, BatchTraversal::Packet, batching, 3);
                CHECK(stream.rays == singles.rays);
                CHECK(stream.pixels == singles.pixels);
            }
        }
    }
}

namespace {

// Records `n` batches of way `way` at `ns_per_ray`, each chosen by the chooser first (as the tracer does).
void run_batches(StreamChooser& chooser, int n, const std::array<double, 2>& ns_per_ray, int& paths) {
    for (int i = 0; i < n; ++i) {
        const StreamChooser::Way way = chooser.next(StreamBatching::Measured);
        paths += way == StreamChooser::Way::Paths;
        chooser.record(way, uint64_t(1000 * ns_per_ray[size_t(way)]), 1000, true);
    }
}

}  // namespace

TEST_CASE("the stream tracer's chooser tries both ways, then keeps to the faster", "[stream]") {
    using Way = StreamChooser::Way;
    SECTION("a way asked for is the only way") {
        StreamChooser chooser;
        CHECK(chooser.next(StreamBatching::Wavefront) == Way::Wavefront);
        CHECK(chooser.next(StreamBatching::Paths) == Way::Paths);
        CHECK(chooser.whole_frame_by_paths(StreamBatching::Paths));
        CHECK(!chooser.whole_frame_by_paths(StreamBatching::Wavefront));
    }
    SECTION("batches in flight together try both ways; a batch that grew its buffers is tried again") {
        StreamChooser chooser;
        CHECK(chooser.next(StreamBatching::Measured) == Way::Wavefront);
        CHECK(chooser.next(StreamBatching::Measured) == Way::Paths);
        chooser.record(Way::Wavefront, 5000, 1000, false);
        chooser.record(Way::Paths, 2000, 1000, true);
        CHECK(!chooser.whole_frame_by_paths(StreamBatching::Measured));
        CHECK(chooser.next(StreamBatching::Measured) == Way::Wavefront);
    }
    SECTION("a way slower by more than kClose is never tried again; paths that win take whole frames") {
        for (const Way slow : {Way::Wavefront, Way::Paths}) {
            StreamChooser chooser;
            std::array<double, 2> cost{1.0, 1.0};
            cost[size_t(slow)] = 1.5;
            int paths = 0;
            run_batches(chooser, 2 * StreamChooser::kProbes, cost, paths);
            CHECK(paths == StreamChooser::kProbes);
            paths = 0;
            run_batches(chooser, 1000, cost, paths);
            CHECK(paths == (slow == Way::Paths ? 0 : 1000));
            CHECK(chooser.whole_frame_by_paths(StreamBatching::Measured) == (slow == Way::Wavefront));
        }
    }
    SECTION("ways within kClose are both measured again, the slower ever more rarely") {
        StreamChooser chooser;
        int paths = 0;
        run_batches(chooser, 1000, {1.0, 1.05}, paths);
        CHECK(paths >= StreamChooser::kProbes);
        CHECK(paths <= StreamChooser::kProbes + 11);  // once at each power of two of the choices after trying
        CHECK(!chooser.whole_frame_by_paths(StreamBatching::Measured));
    }
    SECTION("a first measurement taken in noise is corrected by the retries") {
        StreamChooser chooser;
        int paths = 0;
        run_batches(chooser, 4, {1.0, 0.97}, paths);  // paths looked faster at first
        run_batches(chooser, 2000, {1.0, 1.06}, paths);
        paths = 0;
        run_batches(chooser, 100, {1.0, 1.06}, paths);
        CHECK(paths <= 1);
    }
}

TEST_CASE("Embree's stream rows trace the same paths as its single rows", "[stream]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=1");
    const FlatScene flat = flatten(scene);
    auto embree = make_embree_accelerator(flat, "medium", 0);
    embree->prepare();
    embree->build();
    const Frame single = render_with(*embree, scene, flat, TracerKind::Single, 0);
    const Frame stream = render_with(*embree, scene, flat, TracerKind::Stream, 500);
    // Embree's stream and single kernels may round differently: statistics, not bits.
    CHECK(double(stream.rays) == Approx(double(single.rays)).epsilon(0.001));
    CHECK(stream.mean == Approx(single.mean).epsilon(0.005));
}

TEST_CASE("a frame's batches hold every pixel once, at most the batch size, at least two a thread", "[stream]") {
    struct Case {
        uint64_t width, height, most, threads;
    };
    for (const Case c : {Case{512, 384, 1u << 18, 2}, Case{1024, 768, 1u << 18, 2}, Case{48, 36, 1, 2}, Case{48, 36, 97, 3},
                         Case{48, 36, 1u << 16, 8}, Case{5, 1, 1u << 18, 4}, Case{0, 0, 16, 2}, Case{33, 17, 300, 2}}) {
        INFO(c.width << " x " << c.height << " pixels, batches of at most " << c.most << ", " << c.threads << " threads");
        const BatchPlan plan = BatchPlan::of(c.width, c.height, c.most, c.threads);
        std::vector<int> seen(c.width * c.height, 0);
        for (uint64_t b = 0; b < plan.batches; ++b) {
            uint64_t paths = 0;
            plan.for_each_pixel(b, [&](uint32_t pixel) { ++seen[pixel], ++paths; });
            CHECK(paths <= c.most);
        }
        CHECK(std::all_of(seen.begin(), seen.end(), [](int n) { return n == 1; }));
        // Every thread has batches where there are tiles enough (a frame smaller than one batch included).
        const uint64_t tiles = (c.width + plan.side - 1) / plan.side * ((c.height + plan.side - 1) / plan.side);
        CHECK(plan.batches >= std::min(tiles, c.threads * BatchPlan::kBatchesPerThread));
        if (plan.batches < tiles) CHECK(plan.batches % c.threads == 0);
    }
    // The small-frame case that left a thread idle: 512 x 384 paths, fewer than one batch of 2^18.
    CHECK(BatchPlan::of(512, 384, 1u << 18, 2).batches == 4);
    // A batch's first 16 paths are its first tile's top row: a packet of neighbouring camera rays.
    std::vector<uint32_t> first;
    BatchPlan::of(1024, 768, 1u << 18, 2).for_each_pixel(1, [&](uint32_t pixel) { first.push_back(pixel); });
    for (uint32_t i = 0; i < 17; ++i) CHECK(first[i] == (i < 16 ? 16 + i : 1024 + 16));
}
