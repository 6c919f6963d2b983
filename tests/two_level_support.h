#pragma once
// Two-level test support: a scene of instanced, transformed, overlapping objects, and the comparison of an
// accelerator's hits with brute force over the flattened world triangles.
#include "oracle.h"
#include "renderer/frames.h"

#include <glm/gtc/matrix_transform.hpp>

namespace canopy::test {

// Two generated meshes (a box room of several objects, a bumpy surface), placed by identity, by a rotation with
// non-uniform scale, and by overlapping translated copies.
inline Scene instanced_scene() {
    Scene room = load_scene("gen:box?tris=1500&seed=4");
    const Scene surface = load_scene("gen:surface?tris=1200&seed=5");
    Scene scene = room;
    scene.meshes.push_back(surface.meshes.at(0));
    const uint32_t bump = uint32_t(scene.meshes.size() - 1);
    const BBox box = flatten(room).bounds;
    const float size = glm::length(box.extent());
    glm::mat4 turned = glm::translate(glm::mat4(1.0f), box.center());
    turned = glm::rotate(turned, 0.7f, glm::normalize(Vec3(1, 2, 3)));
    turned = glm::scale(turned, Vec3(0.2f, 0.05f, 0.1f) * size / glm::length(flatten(surface).bounds.extent()));
    scene.instances = {{0, glm::mat4(1.0f)}, {bump, turned}};
    for (int i = 1; i <= 3; ++i)
        scene.instances.push_back({bump, glm::translate(glm::mat4(1.0f), Vec3(0.03f * float(i) * size, 0, 0)) * turned});
    return scene;
}

// Hits agree with brute force over the flat triangles: the same triangle, or the same distance up to the
// rounding of transformed rays (object space) against transformed vertices (world space). Rays that start on a
// surface (one in four of random_rays) may or may not re-hit it at t ~ 1e-7 depending on that rounding: those
// within `touch` of their origin are not compared (the renderer offsets such origins, section 3.9 of pbrt).
inline size_t disagreements_of(const std::vector<Ray>& rays, const std::vector<Hit>& expected,
                               const std::vector<Hit>& actual, float touch) {
    size_t bad = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit& hit = actual[i];
        if ((hit.found() && hit.t < touch) || (expected[i].found() && expected[i].t < touch)) continue;
        if (hit.found() != expected[i].found()) ++bad;
        else if (hit.found() && hit.prim != expected[i].prim && std::abs(hit.t - expected[i].t) > 1e-4f * expected[i].t) ++bad;
    }
    return bad;
}

inline size_t disagreements(const Accelerator& accel, const std::vector<Ray>& rays, const std::vector<Hit>& expected, float touch) {
    std::vector<Hit> actual(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) actual[i] = accel.trace(rays[i]);
    return disagreements_of(rays, expected, actual, touch);
}

}  // namespace canopy::test
