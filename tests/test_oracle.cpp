// Every builder x kernel agrees with brute force on random rays.
#include "oracle.h"

#include <filesystem>

using namespace canopy;
using namespace canopy::test;

TEST_CASE("builders and kernels agree with brute force on procedural scenes", "[oracle]") {
    const char* specs[] = {"gen:box?tris=12000&seed=3", "gen:cylinders?tris=12000&seed=4",
                           "gen:surface?tris=12000&seed=5", "gen:triangles?tris=3000&seed=6"};
    for (const char* spec : specs) {
        const FlatScene flat = flatten(load_scene(spec));
        check_against_oracle(flat.triangles, random_rays(flat.triangles, 100000, 17), spec);
    }
}

TEST_CASE("builders and kernels agree with brute force on shared scenes", "[oracle][shared]") {
    const char* scenes[] = {"stanford-bunny", "sibenik", "crytek-sponza"};
    for (const char* name : scenes) {
        const std::filesystem::path path = std::filesystem::path(CANOPY_SHARED_SCENES) / name / "scene.json";
        if (!std::filesystem::exists(path)) {
            WARN("skipped: " << path << " is absent");
            continue;
        }
        const FlatScene flat = flatten(load_scene(path.string()));
        check_against_oracle(flat.triangles, random_rays(flat.triangles, 10000, 23), name);
    }
}

TEST_CASE("rays with bounded intervals agree with brute force", "[oracle]") {
    const FlatScene flat = flatten(load_scene("gen:box?tris=4000&seed=8"));
    std::vector<Ray> rays = random_rays(flat.triangles, 20000, 29);
    const float diagonal = glm::length(flat.bounds.extent());
    for (size_t i = 0; i < rays.size(); ++i) {
        rays[i].tmin = (i % 3 == 0) ? 0.05f * diagonal : 0.0f;
        rays[i].tmax = (i % 2 == 0) ? 0.3f * diagonal : rays[i].tmax;
    }
    check_against_oracle(flat.triangles, rays, "box with tmin/tmax");
}

TEST_CASE("Möller–Trumbore kernels agree with brute-force Möller–Trumbore", "[oracle][fast]") {
    for (const char* spec : {"gen:box?tris=12000&seed=3", "gen:cylinders?tris=12000&seed=4"}) {
        const FlatScene flat = flatten(load_scene(spec));
        check_against_oracle<true, MollerTrumboreRay>(flat.triangles, off_surface(random_rays(flat.triangles, 60000, 19)), spec);
    }
}

TEST_CASE("fast traversal loses at most a few grazing rays", "[oracle][fast]") {
    // Without the padding of the far distance a box may be culled by rounding: allow 1 ray in 10,000.
    const FlatScene flat = flatten(load_scene("gen:surface?tris=12000&seed=5"));
    const std::vector<Ray> rays = random_rays(flat.triangles, 50000, 21);
    check_against_oracle<false, WatertightRay>(flat.triangles, rays, "surface, fast traversal", rays.size() / 10000);
}
