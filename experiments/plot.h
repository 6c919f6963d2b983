#pragma once
// Log-log line plots as PNG, for the figures of `canopy tradeoff` and `canopy accuracy`: decade grid, labelled
// axes, one coloured polyline per series and a legend. Text is drawn by OpenImageIO with DejaVu Sans
// (Debian's fonts-dejavu-core, installed by scripts/setup.sh).
#include <string>
#include <utility>
#include <vector>

namespace canopy {

struct PlotSeries {
    std::string label;
    std::vector<std::pair<double, double>> points;  // (x, y), both > 0; others are skipped
};

struct LogLogPlot {
    std::string title, x_label, y_label;
    std::vector<PlotSeries> series;
};

// Throws std::runtime_error naming the path when the PNG or its text cannot be written.
void write_plot_png(const LogLogPlot& plot, const std::string& path, int width = 900, int height = 600);

}  // namespace canopy
