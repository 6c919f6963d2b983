// Tree quality metrics against hand-computed values.
#include "accel/metrics.h"
#include "oracle.h"

#include <tbb/global_control.h>

using namespace canopy;
using namespace canopy::test;

TEST_CASE("clipped areas of a triangle", "[metrics]") {
    const Triangle t{Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0)};  // area 2
    CHECK(clipped_area(t, {Vec3(-1), Vec3(3)}) == Approx(2.0));
    CHECK(clipped_area(t, {Vec3(0, 0, -1), Vec3(1, 1, 1)}) == Approx(1.0));   // the unit square corner
    CHECK(clipped_area(t, {Vec3(1, 0, -1), Vec3(3, 3, 1)}) == Approx(0.5));   // x >= 1: a triangle of legs 1
    CHECK(clipped_area(t, {Vec3(5, 5, 5), Vec3(6, 6, 6)}) == 0.0);
    CHECK(clipped_area(t, {Vec3(0, 0, 0.5f), Vec3(2, 2, 1)}) == 0.0);        // above the plane
}

TEST_CASE("EPO is zero when no node overlaps another's surfaces", "[metrics]") {
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},
                                     {Vec3(5, 0, 0), Vec3(6, 0, 0), Vec3(5, 1, 0)}};
    Bvh bvh;
    bvh.nodes = {{{Vec3(0, 0, 0), Vec3(6, 1, 0)}, 1, 0}, {BBox::of(tris[0]), 0, 1}, {BBox::of(tris[1]), 1, 1}};
    bvh.refs = {0, 1};
    CHECK(epo_cost(bvh, tris) == 0.0);
}

TEST_CASE("EPO counts surfaces inside a node that its subtree does not hold", "[metrics]") {
    // A: plane z = y / 4 over [0,4]^2, box [0,4]x[0,4]x[0,1], area sqrt(272) / 2. B: area 0.5 at z = 0.5,
    // inside A's box. A's leaf (C = 1 * 1 triangle) overlaps all of B; B's flat box meets A in a line only.
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(0, 4, 1)},
                                     {Vec3(1, 1, 0.5f), Vec3(2, 1, 0.5f), Vec3(1, 2, 0.5f)}};
    Bvh bvh;
    bvh.nodes = {{merge(BBox::of(tris[0]), BBox::of(tris[1])), 1, 0}, {BBox::of(tris[0]), 0, 1}, {BBox::of(tris[1]), 1, 1}};
    bvh.refs = {0, 1};
    const double total_area = std::sqrt(272.0) / 2.0 + 0.5;
    CHECK(epo_cost(bvh, tris) == Approx(0.5 / total_area));
    CHECK(epo_cost(bvh, tris, {1.2f, 3.0f}) == Approx(3.0 * 0.5 / total_area));  // scales with C_tri
}

TEST_CASE("EPO does not count a split triangle's own pieces as overlap", "[metrics]") {
    // Triangle 0 is referenced by two leaves (split at x = 1); triangle 1 lies far away.
    const std::vector<Triangle> tris{{Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0)},
                                     {Vec3(9, 9, 9), Vec3(10, 9, 9), Vec3(9, 10, 9)}};
    const BBox left{Vec3(0, 0, 0), Vec3(1, 2, 0)}, right{Vec3(1, 0, 0), Vec3(2, 1, 0)};
    Bvh bvh;
    bvh.nodes = {{merge(merge(left, right), BBox::of(tris[1])), 1, 0},
                 {merge(left, right), 3, 0},
                 {BBox::of(tris[1]), 2, 1},
                 {left, 0, 1},
                 {right, 1, 1}};
    bvh.refs = {0, 0, 1};
    CHECK(epo_cost(bvh, tris) == 0.0);
    // The same leaves holding another triangle that covers both: now each leaf overlaps it.
    bvh.refs = {1, 1, 0};
    CHECK(epo_cost(bvh, tris) > 0.0);
}

TEST_CASE("EPO of built trees is positive, and the same with 1 and 2 threads", "[metrics]") {
    const FlatScene flat = flatten(load_scene("gen:triangles?tris=2000&seed=5"));
    for (const BuilderEntry& builder : builders()) {
        const Bvh bvh = build_with(builder.name, flat.triangles).binary;
        double one, two;
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
            one = epo_cost(bvh, flat.triangles);
        }
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
            two = epo_cost(bvh, flat.triangles);
        }
        INFO(builder.name);
        CHECK(one > 0.0);  // large overlapping triangles
        CHECK(one == two);
    }
}
