// Loads a scene, builds a BVH with a named builder, casts a few rays from around it towards its centre, and
// prints what they hit.    usage: cast_rays SCENE [BUILDER]
#include <canopy/canopy.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <exception>
#include <string>

int main(int argc, char** argv) {
    if (argc < 2 || argc > 3) {
        std::fprintf(stderr, "usage: cast_rays SCENE [BUILDER]   (SCENE: .obj, .gltf, .glb, scene.json or gen:box)\n");
        return 2;
    }
    try {
        const canopy::TriangleMesh mesh = canopy::load_triangles(argv[1]);
        const canopy::Accel accel({mesh.vertices, mesh.triangles}, {.builder = argc > 2 ? argv[2] : "binned"});
        const canopy::AccelStats stats = accel.stats();
        std::printf("%llu triangles, builder %s, kernel %s, %.1f ms, SAH %.2f\n", (unsigned long long)stats.triangles,
                    stats.builder.c_str(), stats.kernel.c_str(), stats.build_ms, stats.layout_sah.value_or(0.0));

        std::array<float, 3> lower{INFINITY, INFINITY, INFINITY}, upper{-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = 0; i < mesh.vertices.size(); ++i) {
            lower[i % 3] = std::min(lower[i % 3], mesh.vertices[i]);
            upper[i % 3] = std::max(upper[i % 3], mesh.vertices[i]);
        }
        // Eight rays from a ring around the scene, a little above its centre, aimed at the centre.
        for (int k = 0; k < 8; ++k) {
            const float angle = float(k) * 0.785398f;
            std::array<float, 3> origin, direction;
            for (int a = 0; a < 3; ++a) {
                const float centre = 0.5f * (lower[a] + upper[a]), extent = upper[a] - lower[a];
                const float offset = a == 0 ? std::cos(angle) : a == 1 ? 0.25f : std::sin(angle);
                origin[a] = centre + offset * extent;
                direction[a] = centre - origin[a];
            }
            const canopy::RayHit hit = accel.intersect(origin, direction);
            if (hit.found())
                std::printf("ray %d: triangle %u at t = %.4f (u %.3f, v %.3f)\n", k, hit.triangle, hit.t, hit.u, hit.v);
            else
                std::printf("ray %d: miss\n", k);
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "cast_rays: %s\n", e.what());
        return 1;
    }
}
