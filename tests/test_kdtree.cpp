// The SAH kd-tree (accel/kdtree.h) and its kernel (kernels/traverse_kd.h): closest and any hits equal brute force's
// on random, axis-aligned and adversarial rays and scenes; the reference cap bounds huge overlapping triangles; the
// accelerator answers as the renderer and the command line ask.
#include "accel/kdtree.h"
#include "kernels/traverse_kd.h"
#include "oracle.h"
#include "renderer/frames.h"
#include "test_scale.h"

#include <tbb/global_control.h>

#include <cstring>
#include <unordered_map>

using namespace canopy;
using namespace canopy::test;

namespace {

// Builds the kd-tree over `tris` and checks its closest hits against brute force with the same triangle test, and
// its any hits against brute force's found(); returns the tree for further checks.
template <class TriangleTest = WatertightRay>
KdTree check_kd_against_oracle(std::span<const Triangle> tris, const std::vector<Ray>& rays, const std::string& what,
                               const KdSettings& settings = {}) {
    const KdTree tree = build_kdtree(tris, settings);
    const std::vector<Hit> expected = brute_force_all<TriangleTest>(tris, rays);
    std::vector<Hit> actual(rays.size());
    std::vector<char> any(rays.size());
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) {
        traverse_kd<Query::Closest, TriangleTest>(tree, rays[i], actual[i]);
        Hit unused;
        any[i] = traverse_kd<Query::Any, TriangleTest>(tree, rays[i], unused);
    });
    CHECK(count_mismatches(rays, expected, actual, what + " / kdtree") == 0);
    size_t any_mismatches = 0;
    for (size_t i = 0; i < rays.size(); ++i) any_mismatches += bool(any[i]) != expected[i].found();
    INFO(what << " / kdtree: any-hit disagreements");
    CHECK(any_mismatches == 0);
    return tree;
}

std::vector<Triangle> transformed(std::vector<Triangle> tris, float scale, const Vec3& offset) {
    for (Triangle& t : tris) t = {t.v0 * scale + offset, t.v1 * scale + offset, t.v2 * scale + offset};
    return tris;
}

// Unit cubes on an integer grid, every face two triangles, and unit squares lying in the planes x = i: every
// vertex coordinate an integer, so every candidate plane is one that triangles lie in, start or end on.
std::vector<Triangle> axis_aligned_cells(int n) {
    std::vector<Triangle> tris;
    auto quad = [&](Vec3 a, Vec3 b, Vec3 c, Vec3 d) { tris.insert(tris.end(), {{a, b, c}, {a, c, d}}); };
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            if ((i + j) % 3 == 0) {
                const Vec3 o(2 * i, 2 * j, (i * j) % 4);
                for (int k = 0; k < 3; ++k) {
                    Vec3 u(0), v(0), w(0);
                    u[(k + 1) % 3] = 1, v[(k + 2) % 3] = 1, w[k] = 1;
                    quad(o, o + u, o + u + v, o + v);
                    quad(o + w, o + w + v, o + w + u + v, o + w + u);
                }
            } else {
                const Vec3 o(2 * i, 2 * j, 1);
                quad(o, o + Vec3(0, 1, 0), o + Vec3(0, 1, 1), o + Vec3(0, 0, 1));
            }
        }
    return tris;
}

// Rays lying in candidate planes, parallel to them (zero and negative-zero components), starting on them, and
// along the grid lines, besides random ones.
std::vector<Ray> axis_aligned_rays(int n, size_t count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<int> cell(-1, 2 * n + 1);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    const Vec3 axes[] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}, {-0.0f, 0, 1}, {0, -0.0f, -1}};
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        const Vec3 on_grid(float(cell(rng)), float(cell(rng)), float(cell(rng) % 5));
        Ray ray;
        switch (i % 4) {
            case 0: ray = {on_grid, axes[rng() % 8]}; break;  // along grid lines, lying in two planes
            case 1: {  // in the plane x = integer, or parallel to it through half-integers
                const Vec3 d = glm::normalize(Vec3(0.0f, unit(rng), unit(rng)) + Vec3(0, 1e-3f, 0));
                ray = {on_grid + Vec3(0, 0.5f * float(i % 3), 0.25f), d};
                break;
            }
            case 2: ray = {on_grid, glm::normalize(Vec3(unit(rng), unit(rng), unit(rng)) + Vec3(1e-3f))}; break;  // from a plane
            default: {  // from a point on a plane towards a grid point: leaves cells exactly through planes and edges
                const Vec3 to(float(cell(rng)), float(cell(rng)), float(cell(rng) % 5));
                ray = {on_grid + Vec3(0.5f, 0, 0), to == on_grid + Vec3(0.5f, 0, 0) ? Vec3(0, 0, 1) : glm::normalize(to - on_grid - Vec3(0.5f, 0, 0))};
            }
        }
        rays.push_back(ray);
    }
    return rays;
}

bool has_split(const KdTree& tree, int axis, float position) {
    return std::any_of(tree.nodes.begin(), tree.nodes.end(), [&](const KdNode& node) {
        return !node.is_leaf() && node.axis() == axis && node.split == position;
    });
}

}  // namespace

TEST_CASE("the kd-tree agrees with brute force on procedural scenes", "[kdtree][oracle]") {
    const std::string specs[] = {scaled_spec("box", 12000, 3), scaled_spec("cylinders", 12000, 4),
                                 scaled_spec("mirror", 12000, 7), scaled_spec("surface", 12000, 5),
                                 scaled_spec("triangles", 3000, 6)};
    for (const std::string& spec : specs) {
        const FlatScene flat = flatten(load_scene(spec));
        check_kd_against_oracle(flat.triangles, random_rays(flat.triangles, scaled(100000), 17), spec);
    }
}

TEST_CASE("the kd-tree agrees with brute force at extreme scales and offsets", "[kdtree][oracle]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("box", 4000, 8)));
    for (const auto& [scale, offset] : {std::pair{1.0f, Vec3(0)}, std::pair{1.0f, Vec3(1e5f, -1e5f, 1e5f)},
                                        std::pair{1e-4f, Vec3(0)}, std::pair{1e4f, Vec3(0)}, std::pair{1.0f, Vec3(1e7f)}}) {
        const std::vector<Triangle> tris = transformed(flat.triangles, scale, offset);
        check_kd_against_oracle(tris, random_rays(tris, scaled(20000), 31),
                                "box x" + std::to_string(scale) + " + " + std::to_string(offset.x));
    }
}

TEST_CASE("the kd-tree agrees with brute force on shared scenes", "[kdtree][oracle][shared]") {
    for_each_shared_scene([](const FlatScene& flat, const char* name) {
        check_kd_against_oracle(flat.triangles, random_rays(flat.triangles, scaled(10000, 1000), 23), name);
    });
}

TEST_CASE("kd-tree rays with bounded intervals agree with brute force", "[kdtree][oracle]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("box", 4000, 8)));
    check_kd_against_oracle(flat.triangles, bounded_interval_rays(flat, scaled(20000), 29), "box with tmin/tmax");
}

TEST_CASE("the kd-tree's Möller–Trumbore kernel agrees with brute-force Möller–Trumbore", "[kdtree][oracle][fast]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("cylinders", 12000, 4)));
    check_kd_against_oracle<MollerTrumboreRay>(flat.triangles, off_surface(random_rays(flat.triangles, scaled(40000), 19)),
                                               "cylinders, Möller–Trumbore");
}

TEST_CASE("axis-aligned triangles in split planes, rays in, along and from the planes", "[kdtree][robustness]") {
    const int n = 24;
    const std::vector<Triangle> tris = axis_aligned_cells(n);
    const KdTree tree = check_kd_against_oracle(tris, axis_aligned_rays(n, 40000, 5), "axis-aligned cells");
    // The scene's planes are the tree's: some split lies where triangles lie, start and end.
    bool on_a_face = false;
    for (int i = 0; i <= 2 * n && !on_a_face; ++i) on_a_face = has_split(tree, 0, float(i));
    CHECK(on_a_face);
}

TEST_CASE("a ray through a shared edge lying in a split plane hits one of its triangles", "[kdtree][watertight]") {
    // A floor z = 0 of unit squares, each two triangles; x-splits can only fall on the edges x = i between them.
    const int n = 32;
    std::vector<Triangle> tris;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const Vec3 a(i, j, 0), b(i + 1, j, 0), c(i + 1, j + 1, 0), d(i, j + 1, 0);
            tris.insert(tris.end(), {{a, b, c}, {a, c, d}});
        }
    const KdTree tree = build_kdtree(tris);
    float edge = -1.0f;
    for (int i = 1; i < n && edge < 0.0f; ++i)
        if (has_split(tree, 0, float(i))) edge = float(i);
    REQUIRE(edge > 0.0f);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    size_t leaks = 0;
    for (int k = 0; k < 2000; ++k) {
        const Vec3 target(edge, 1.0f + float(n - 2) * unit(rng), 0.0f);
        // Straight down in the plane x = edge (zero and negative-zero x), and slanted within that plane.
        const Vec3 from = target + Vec3(0.0f, unit(rng) - 0.5f, 1.0f + unit(rng));
        for (const Ray& ray : {Ray{target + Vec3(0, 0, 1), {k % 2 ? -0.0f : 0.0f, 0, -1}}, Ray{from, glm::normalize(target - from)}}) {
            Hit hit;
            leaks += !traverse_kd<Query::Closest>(tree, ray, hit) + !any_hit_kd(tree, ray);
        }
    }
    CHECK(leaks == 0);
}

TEST_CASE("the reference cap bounds huge overlapping triangles, and the tree stays correct", "[kdtree][pathological]") {
    // Thousands of triangles each spanning the whole scene: every split straddles all of them.
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::vector<Triangle> tris;
    for (size_t i = 0; i < scaled(3000, 500); ++i) {
        const Vec3 c(0.05f * unit(rng), 0.05f * unit(rng), 0.05f * unit(rng));
        tris.push_back({c + Vec3(-100, unit(rng), unit(rng)), c + Vec3(100, 100 * unit(rng), unit(rng)),
                        c + Vec3(unit(rng), -100, 100 * unit(rng))});
    }
    const std::vector<Ray> rays = random_rays(tris, scaled(10000), 41);
    for (const double cap : {KdSettings{}.max_references_per_triangle, 1.5}) {
        KdSettings settings;
        settings.max_references_per_triangle = cap;
        const KdTree tree = check_kd_against_oracle(tris, rays, "huge overlapping triangles, cap " + std::to_string(cap), settings);
        CHECK(double(kd_stats(tree, tris.size()).references) <= cap * double(tris.size()));
        CHECK(tree.depth <= kKdMaxDepth);
    }
}

TEST_CASE("the kd-tree is the same with 1 and 2 threads", "[kdtree][determinism]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("cylinders", 60000, 4)));
    const auto build_on = [&](int threads) {
        const tbb::global_control control(tbb::global_control::max_allowed_parallelism, size_t(threads));
        return build_kdtree(flat.triangles);
    };
    const KdTree one = build_on(1), two = build_on(2);
    REQUIRE(one.nodes.size() == two.nodes.size());
    CHECK(std::memcmp(one.nodes.data(), two.nodes.data(), one.nodes.size() * sizeof(KdNode)) == 0);
    REQUIRE(one.leaf_blocks.size() == two.leaf_blocks.size());
    CHECK(std::memcmp(one.leaf_blocks.data(), two.leaf_blocks.data(), one.leaf_blocks.size() * sizeof(KdBlock)) == 0);
}

// Checks the counting kernel's leaf records: each visited leaf's count is its real triangles, not its lanes, and the
// bytes it reads are its whole blocks.
struct LeafCounter {
    std::unordered_map<const KdBlock*, uint32_t> count_at;  // a non-empty leaf's first block: its triangles
    uint32_t last_count = 0;
    uint64_t visits = 0, wrong = 0;

    explicit LeafCounter(const KdTree& tree) {
        for (const KdNode& node : tree.nodes)
            if (node.is_leaf() && node.count()) count_at[&tree.leaf_blocks[node.first]] = node.count();
    }
    void inner() {}
    void leaf() {}
    void triangles(uint32_t n) { last_count = n; }
    void touch(const void* p, size_t bytes) {
        const auto leaf = count_at.find(static_cast<const KdBlock*>(p));
        if (leaf == count_at.end()) return;  // a node
        ++visits;
        wrong += leaf->second != last_count || bytes != kd_blocks(leaf->second) * sizeof(KdBlock);
    }
};

// Every leaf's blocks: its triangles in lanes 0 to count - 1, the scene's vertices and index, then padding lanes
// (prim kNone, a degenerate triangle at the origin); returns the references, padding not counted.
uint64_t check_leaf_blocks(const KdTree& tree, std::span<const Triangle> tris) {
    uint64_t references = 0, blocks = 0, wrong = 0;
    for (const KdNode& node : tree.nodes) {
        if (!node.is_leaf()) continue;
        for (uint32_t lane = 0; lane < kd_blocks(node.count()) * kKdLanes; ++lane) {
            const KdBlock& block = tree.leaf_blocks.at(node.first + lane / kKdLanes);
            const uint32_t l = lane % kKdLanes, prim = block.prim[l];
            const bool used = lane < node.count();
            const Triangle t = used && prim < tris.size() ? tris[prim] : Triangle{Vec3(0), Vec3(0), Vec3(0)};
            wrong += used ? prim >= tris.size() : prim != KdBlock::kNone;
            const Vec3* vertices[3] = {&t.v0, &t.v1, &t.v2};
            for (int v = 0; v < 3; ++v)
                for (int a = 0; a < 3; ++a) wrong += block.v[v][a][l] != (*vertices[v])[a];
        }
        references += node.count();
        blocks += kd_blocks(node.count());
    }
    CHECK(wrong == 0);
    CHECK(blocks == tree.leaf_blocks.size());
    CHECK(tree.bytes() == tree.nodes.size() * sizeof(KdNode) + blocks * sizeof(KdBlock));
    return references;
}

TEST_CASE("kd leaves are SIMD blocks whose padding lanes are never hit nor counted", "[kdtree][blocks]") {
    // Small triangles around the origin, none through it, where the padding lanes' degenerate triangles lie; rays
    // through the origin besides random ones. A high traversal cost makes leaves of more triangles than a block's
    // lanes, so leaves take one block, several, and part-filled ones.
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::vector<Triangle> tris;
    while (tris.size() < 3000) {
        const Vec3 c(10.0f * unit(rng), 10.0f * unit(rng), 10.0f * unit(rng));
        if (glm::length(c) < 2.0f) continue;
        tris.push_back({c + 0.3f * Vec3(unit(rng), unit(rng), unit(rng)), c + 0.3f * Vec3(unit(rng), unit(rng), unit(rng)),
                        c + 0.3f * Vec3(unit(rng), unit(rng), unit(rng))});
    }
    std::vector<Ray> rays = random_rays(tris, 5000, 43);
    for (int i = 0; i < 5000; ++i) {
        const Vec3 from = 15.0f * glm::normalize(Vec3(unit(rng), unit(rng), unit(rng)) + Vec3(1e-3f));
        rays.push_back(i % 2 ? Ray{from, -glm::normalize(from)} : Ray{Vec3(0.0f), glm::normalize(from)});
    }
    for (const float traversal : {KdSettings{}.traversal, 400.0f}) {
        KdSettings settings;
        settings.traversal = traversal;
        const std::string what = "blocks, K_T " + std::to_string(traversal);
        const KdTree tree = check_kd_against_oracle(tris, rays, what, settings);
        const uint64_t references = check_leaf_blocks(tree, tris);
        CHECK(kd_stats(tree, tris.size()).references == references);
        CHECK(kd_stats(tree, tris.size()).refs_per_triangle == double(references) / double(tris.size()));
        bool part_filled = false, several = false;
        for (const KdNode& node : tree.nodes) {
            part_filled |= node.is_leaf() && node.count() % kKdLanes != 0;
            several |= node.is_leaf() && node.count() > uint32_t(kKdLanes);
        }
        CHECK(part_filled);
        if (traversal > KdSettings{}.traversal) CHECK(several);
        // The counting kernel counts real triangles and reads whole blocks.
        LeafCounter counter(tree);
        Hit hit;
        for (const Ray& ray : rays) traverse_kd<Query::Closest>(tree, ray, hit, counter);
        CHECK(counter.visits > 0);
        CHECK(counter.wrong == 0);
    }
}

TEST_CASE("kd-tree settings outside their domain are refused", "[kdtree]") {
    const std::vector<Triangle> tris = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
    KdSettings bonus;
    bonus.empty_bonus = 1.5f;
    CHECK_THROWS_AS(build_kdtree(tris, bonus), std::invalid_argument);
    KdSettings cap;
    cap.max_references_per_triangle = 0.5;
    CHECK_THROWS_AS(build_kdtree(tris, cap), std::invalid_argument);
}

TEST_CASE("the kd-tree's SAH is below a single leaf's, and its statistics count its nodes", "[kdtree][metrics]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("box", 4000, 8)));
    const KdTree tree = build_kdtree(flat.triangles);
    const KdStats stats = kd_stats(tree, flat.triangles.size());
    CHECK(kd_sah_cost(tree) < double(flat.triangles.size()));  // a single leaf's SAH: C_tri N
    CHECK(stats.nodes == tree.nodes.size());
    CHECK(stats.leaves == (stats.nodes + 1) / 2);  // every inner node has two children
    CHECK(stats.refs_per_triangle >= 1.0);
    CHECK(stats.depth <= kKdMaxDepth);
}

TEST_CASE("the kdtree accelerator renders, counts and reports as the BVH accelerators do", "[kdtree][render]") {
    const Scene scene = load_scene("gen:box?tris=3000&seed=2");
    const FlatScene flat = flatten(scene);
    const auto kd = make_canopy_accelerator(scene, flat, {.builder = "kdtree"});
    const auto binned = make_canopy_accelerator(scene, flat, {.builder = "binned"});
    for (Accelerator* a : {kd.get(), binned.get()}) a->prepare(), a->build();
    CHECK(kd->kernel() == "kd");
    CHECK(kd->builder() == "kdtree");
    const AcceleratorReport r = kd->report(true);
    CHECK_FALSE(r.epo.has_value());
    CHECK(r.sah.has_value());
    CHECK(r.bytes.value_or(0) > 0);

    FrameSettings settings;
    settings.width = 48, settings.height = 32;
    const ShadingScene shading{flat, settings};
    const PinholeCamera camera(scene_camera(scene, flat), settings.width, settings.height);
    Image kd_image(settings.width, settings.height), binned_image(settings.width, settings.height);
    const uint64_t kd_rays = render(*kd, shading, camera, 0, kd_image);
    const uint64_t binned_rays = render(*binned, shading, camera, 0, binned_image);
    CHECK(kd_rays == binned_rays);
    CHECK(kd_image.mean(1) == Approx(binned_image.mean(1)).epsilon(5e-3));  // the bench's bar: paths part only at ties

    FrameSettings stream = settings;
    stream.tracer = TracerKind::Stream;
    Image stream_image(settings.width, settings.height);
    CHECK(render(*kd, {flat, stream}, camera, 0, stream_image) == kd_rays);
    CHECK(stream_image.mean(1) == Approx(kd_image.mean(1)).epsilon(1e-6));

    const auto [counts, rays] = count_frame(*kd, shading, camera, 0);
    CHECK(rays == kd_rays);
    CHECK(counts.inner_nodes > 0);
    CHECK(counts.leaf_nodes > 0);
    CHECK(counts.triangle_tests > 0);
    CHECK(counts.cache_lines >= counts.inner_nodes);  // every node visit reads a line

    const std::vector<Ray> probes = random_rays(flat.triangles, 2000, 7);
    std::vector<Hit> batch(probes.size());
    kd->trace_batch(Query::Closest, probes, batch);
    for (size_t i = 0; i < probes.size(); ++i) CHECK(batch[i].t == kd->trace(probes[i]).t);
}

TEST_CASE("the kdtree accelerator refuses two-level top levels and start trees", "[kdtree][render]") {
    const Scene scene = load_scene("gen:box?tris=500&seed=2");
    const FlatScene flat = flatten(scene);
    for (const char* top : {"two-level", "rebraid"})
        CHECK_THROWS_WITH(make_canopy_accelerator(scene, flat, {.builder = "kdtree", .toplevel = top}),
                          Catch::Contains("kd-tree") && Catch::Contains(top));
    CHECK_THROWS_AS(make_canopy_accelerator(flat, {.builder = "kdtree", .start = "lbvh"}), std::invalid_argument);
    CHECK_THROWS_WITH(find_builder("kdtree"), Catch::Contains("kd-tree"));
    CHECK_NOTHROW(check_builder_name("kdtree"));
    CHECK_THROWS_WITH(check_builder_name("nosuch"), Catch::Contains("kdtree"));
}
