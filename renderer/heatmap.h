#pragma once
// Traversal-cost heatmaps: what each pixel's primary ray visited, through the counting variant of the kernel.
#include "renderer/frames.h"

#include <string>

namespace canopy {

struct HeatmapStats {
    double mean_inner = 0, mean_leaves = 0, mean_triangles = 0;
    double cost_p99 = 0;  // the cost the PNG's top colour stands for
};

// Writes `exr_path` with channels inner, leaves and triangles (counts per pixel, primary rays through pixel
// centres) and, beside it with the extension .png, a false-colour image of C_inn * inner + C_tri * triangles
// scaled to the image's 99th percentile.
HeatmapStats write_heatmap(const Accelerator& accel, const PinholeCamera& camera, int width, int height,
                           const std::string& exr_path);

}  // namespace canopy
