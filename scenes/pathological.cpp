#include "scenes/pathological.h"

#include "scenes/scene.h"

#include <random>

namespace canopy {

std::vector<Triangle> random_triangles(size_t n) {
    return flatten(load_scene("gen:triangles?tris=" + std::to_string(n) + "&seed=1")).triangles;
}

std::vector<Triangle> identical_triangles(size_t n) {
    return std::vector<Triangle>(n, Triangle{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)});
}

std::vector<Triangle> triangles_in_one_plane(size_t n) {
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<float> in_square(-1.0f, 1.0f), offset(-0.01f, 0.01f);
    std::vector<Triangle> tris(n);
    for (Triangle& t : tris) {
        const Vec3 a(in_square(rng), in_square(rng), 0.0f);
        t = {a, a + Vec3(offset(rng), offset(rng), 0.0f), a + Vec3(offset(rng), offset(rng), 0.0f)};
    }
    return tris;
}

std::vector<Triangle> zero_area_triangles(size_t n) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<float> in_cube(-1.0f, 1.0f), step(-0.05f, 0.05f);
    std::vector<Triangle> tris(n);
    for (size_t i = 0; i < n; ++i) {
        const Vec3 a(in_cube(rng), in_cube(rng), in_cube(rng)), d(step(rng), step(rng), step(rng));
        tris[i] = i % 4 == 0 ? Triangle{a, a, a} : Triangle{a, a + d, a + 3.0f * d};
    }
    return tris;
}

std::vector<Triangle> parallel_needles(size_t n) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<float> in_cube(-1.0f, 1.0f);
    const Vec3 along = glm::normalize(Vec3(1, 1, 1)), across = 1e-4f * glm::normalize(Vec3(1, -1, 0));
    std::vector<Triangle> tris(n);
    for (Triangle& t : tris) {
        const Vec3 a(in_cube(rng), in_cube(rng), in_cube(rng));
        t = {a, a + along, a + across};
    }
    return tris;
}

std::vector<Triangle> scaled_box(size_t n, float scale) {
    std::vector<Triangle> tris = flatten(load_scene("gen:box?tris=" + std::to_string(n) + "&seed=9")).triangles;
    for (Triangle& t : tris) t = {t.v0 * scale, t.v1 * scale, t.v2 * scale};
    return tris;
}

const std::vector<PathologicalScene>& pathological_scenes() {
    static const std::vector<PathologicalScene> scenes{
        {"identical", identical_triangles},
        {"one plane", triangles_in_one_plane},
        {"zero area", zero_area_triangles},
        {"needles", parallel_needles},
        {"box x1e-30", [](size_t n) { return scaled_box(n, 1e-30f); }},
        {"box x1e30", [](size_t n) { return scaled_box(n, 1e30f); }},
    };
    return scenes;
}

}  // namespace canopy
