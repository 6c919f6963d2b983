// Every builder x kernel agrees with brute force on random rays.
#include "oracle.h"
#include "test_scale.h"

using namespace canopy;
using namespace canopy::test;

TEST_CASE("builders and kernels agree with brute force on procedural scenes", "[oracle][heavy]") {
    const std::string specs[] = {scaled_spec("box", 12000, 3), scaled_spec("cylinders", 12000, 4),
                                 scaled_spec("mirror", 12000, 7), scaled_spec("surface", 12000, 5),
                                 scaled_spec("triangles", 3000, 6), scaled_spec("foliage", 6000, 8),
                                 scaled_spec("city", 6000, 9), scaled_spec("room", 6000, 10)};
    for (const std::string& spec : specs) {
        const FlatScene flat = flatten(load_scene(spec));
        check_against_oracle(flat.triangles, random_rays(flat.triangles, scaled(100000), 17), spec);
    }
}

TEST_CASE("builders and kernels agree with brute force on shared scenes", "[oracle][shared][heavy]") {
    for_each_shared_scene([](const FlatScene& flat, const char* name) {
        check_against_oracle(flat.triangles, random_rays(flat.triangles, scaled(10000, 1000), 23), name);
    });
}

TEST_CASE("rays with bounded intervals agree with brute force", "[oracle]") {
    const FlatScene flat = flatten(load_scene(scaled_spec("box", 4000, 8)));
    check_against_oracle(flat.triangles, bounded_interval_rays(flat, scaled(20000), 29), "box with tmin/tmax");
}

TEST_CASE("Möller–Trumbore kernels agree with brute-force Möller–Trumbore", "[oracle][fast][heavy]") {
    for (const std::string& spec : {scaled_spec("box", 12000, 3), scaled_spec("cylinders", 12000, 4)}) {
        const FlatScene flat = flatten(load_scene(spec));
        check_against_oracle<true, MollerTrumboreRay>(flat.triangles, off_surface(random_rays(flat.triangles, scaled(60000), 19)), spec);
    }
}

TEST_CASE("fast traversal loses at most a few grazing rays", "[oracle][fast]") {
    // Without the padding of the far distance a box may be culled by rounding: allow 1 ray in 10,000 (at least
    // one, for the few rays of a scaled-down run).
    const FlatScene flat = flatten(load_scene(scaled_spec("surface", 12000, 5)));
    const std::vector<Ray> rays = random_rays(flat.triangles, scaled(50000), 21);
    check_against_oracle<false, WatertightRay>(flat.triangles, rays, "surface, fast traversal",
                                               std::max<size_t>(1, rays.size() / 10000));
}
