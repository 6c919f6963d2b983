// Emitting materials (OBJ Ke, glTF emissiveFactor) under --materials: a path that hits an emitter gathers its
// emission, weighted by what the path carried there; without --materials the protocol's image is unchanged.
#include "oracle.h"
#include "renderer/path_tracer.h"

using namespace canopy;
using namespace canopy::test;

namespace {

// A lamp: a square facing the camera that fills its whole view, with nothing behind the camera.
FlatScene lamp_filling_the_view(const Vec3& kd, const Vec3& emission) {
    FlatScene flat;
    const Vec3 a(-10, -10, -1), b(10, -10, -1), c(10, 10, -1), d(-10, 10, -1);
    flat.triangles = {{a, b, c}, {a, c, d}};
    flat.materials = {{"lamp", kd, emission}};
    flat.material = {0, 0};
    flat.has_emitters = emission != Vec3(0.0f);
    for (const Triangle& t : flat.triangles) flat.bounds.extend(BBox::of(t));
    return flat;
}

// Every pixel of one frame of 4x3 pixels.
std::vector<Vec3> render_pixels(const FlatScene& flat, bool materials, int bounces) {
    FrameSettings settings;
    settings.width = 4, settings.height = 3, settings.max_bounces = bounces;
    settings.material_albedo = materials;
    const ShadingScene shading{flat, settings};
    Image image(settings.width, settings.height);
    const Camera camera{{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 60.0f};
    render_frame(BruteForceTracer{flat.triangles}, shading, PinholeCamera(camera, settings.width, settings.height), 0, image);
    const std::vector<float> rgb = image.average(1);
    std::vector<Vec3> pixels;
    for (size_t i = 0; i < rgb.size(); i += 3) pixels.emplace_back(rgb[i], rgb[i + 1], rgb[i + 2]);
    return pixels;
}

}  // namespace

TEST_CASE("an emitter seen directly has exactly its emitted radiance", "[render][emission]") {
    const FlatScene lamp = lamp_filling_the_view(Vec3(0.5f, 0.25f, 0.5f), Vec3(17, 12, 4));
    for (const Vec3& pixel : render_pixels(lamp, true, 0)) CHECK(pixel == Vec3(17, 12, 4));
}

TEST_CASE("emission is added before the albedo weights the rest of the path", "[render][emission]") {
    // One bounce leaves the lamp towards the camera's side, where only the white sky is: emission + albedo x 1.
    const FlatScene lamp = lamp_filling_the_view(Vec3(0.5f, 0.25f, 0.5f), Vec3(17, 12, 4));
    for (const Vec3& pixel : render_pixels(lamp, true, 1)) CHECK(pixel == Vec3(17.5f, 12.25f, 4.5f));
}

TEST_CASE("without --materials an emitter is a grey diffuse surface, as the protocol wants", "[render][emission]") {
    const FlatScene lamp = lamp_filling_the_view(Vec3(0.5f), Vec3(17, 12, 4));
    for (const Vec3& pixel : render_pixels(lamp, false, 0)) CHECK(pixel == Vec3(0.0f));
    for (const Vec3& pixel : render_pixels(lamp, false, 1)) CHECK(pixel == Vec3(0.8f));
}
