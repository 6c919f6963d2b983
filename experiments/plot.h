#pragma once
// Plots as PNG: log-log line plots for the figures of `canopy tradeoff` and `canopy accuracy` (decade grid,
// labelled axes, one coloured polyline per series and a legend), and panels of labelled points on linear axes for
// `canopy study`. Text is drawn by OpenImageIO with DejaVu Sans
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

struct ScatterPoint {
    double x, y;
    std::string label;  // drawn beside the point
};

struct ScatterPanel {
    std::string title, subtitle;
    std::vector<ScatterPoint> points;  // non-finite ones are skipped
};

// Panels side by side, each with its own linear axes and the least-squares line through its points.
struct ScatterPlot {
    std::string x_label, y_label;
    std::vector<ScatterPanel> panels;
};

// Throws as write_plot_png.
void write_scatter_png(const ScatterPlot& plot, const std::string& path, int panel_width = 480, int height = 460);

}  // namespace canopy
