#include "renderer/heatmap.h"

#include <OpenImageIO/imageio.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <stdexcept>

namespace canopy {
namespace {

// A ramp from dark blue through cyan, green and yellow to red, linear between its stops.
Vec3 false_colour(float x) {
    static constexpr std::array<Vec3, 6> stops = {Vec3(0.05f, 0.03f, 0.25f), Vec3(0.1f, 0.3f, 0.9f),
                                                  Vec3(0.1f, 0.8f, 0.9f),   Vec3(0.2f, 0.85f, 0.2f),
                                                  Vec3(0.95f, 0.9f, 0.1f),  Vec3(0.9f, 0.1f, 0.05f)};
    const float t = std::clamp(x, 0.0f, 1.0f) * float(stops.size() - 1);
    const size_t i = std::min(size_t(t), stops.size() - 2);
    return glm::mix(stops[i], stops[i + 1], t - float(i));
}

void write_image(const std::string& path, int width, int height, const std::vector<std::string>& channels,
                 OIIO::TypeDesc type, const void* pixels) {
    auto out = OIIO::ImageOutput::create(path);
    if (!out) throw std::runtime_error(path + ": cannot create image output: " + OIIO::geterror());
    OIIO::ImageSpec spec(width, height, int(channels.size()), type);
    spec.channelnames = channels;
    if (!out->open(path, spec) || !out->write_image(type, pixels) || !out->close())
        throw std::runtime_error(path + ": cannot write image: " + out->geterror());
}

}  // namespace

HeatmapStats write_heatmap(const Accelerator& accel, const PinholeCamera& camera, int width, int height,
                           const std::string& exr_path) {
    const size_t pixels = size_t(width) * size_t(height);
    std::vector<float> counts(pixels * 3);
    tbb::parallel_for(0, height, [&](int y) {
        for (int x = 0; x < width; ++x) {
            const TraversalCounts c = accel.count(camera.generate(x, y, 0.5f, 0.5f));
            float* p = &counts[(size_t(y) * size_t(width) + size_t(x)) * 3];
            p[0] = float(c.inner_nodes), p[1] = float(c.leaf_nodes), p[2] = float(c.triangle_tests);
        }
    });
    write_image(exr_path, width, height, {"inner", "leaves", "triangles"}, OIIO::TypeDesc::FLOAT, counts.data());

    const SahCosts costs;
    std::vector<float> cost(pixels);
    HeatmapStats stats;
    for (size_t i = 0; i < pixels; ++i) {
        cost[i] = costs.inner * counts[3 * i] + costs.triangle * counts[3 * i + 2];
        stats.mean_inner += counts[3 * i], stats.mean_leaves += counts[3 * i + 1], stats.mean_triangles += counts[3 * i + 2];
    }
    stats.mean_inner /= double(pixels), stats.mean_leaves /= double(pixels), stats.mean_triangles /= double(pixels);
    std::vector<float> sorted = cost;
    std::nth_element(sorted.begin(), sorted.begin() + long(pixels * 99 / 100), sorted.end());
    stats.cost_p99 = std::max(1.0f, sorted[pixels * 99 / 100]);
    std::vector<uint8_t> rgb(pixels * 3);
    for (size_t i = 0; i < pixels; ++i) {
        const Vec3 c = false_colour(float(cost[i] / stats.cost_p99));
        for (int k = 0; k < 3; ++k) rgb[3 * i + size_t(k)] = uint8_t(std::lround(c[k] * 255.0f));
    }
    const std::string png = std::filesystem::path(exr_path).replace_extension(".png").string();
    write_image(png, width, height, {"R", "G", "B"}, OIIO::TypeDesc::UINT8, rgb.data());
    return stats;
}

}  // namespace canopy
