#include "experiments/plot.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <stdexcept>

namespace canopy {
namespace {

constexpr const char* kFont = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

// Distinct colours for up to ten series (Tableau 10), then they repeat.
constexpr float kPalette[10][3] = {{0.12f, 0.47f, 0.71f}, {1.0f, 0.5f, 0.05f}, {0.17f, 0.63f, 0.17f},
                                   {0.84f, 0.15f, 0.16f}, {0.58f, 0.4f, 0.74f}, {0.55f, 0.34f, 0.29f},
                                   {0.89f, 0.47f, 0.76f}, {0.5f, 0.5f, 0.5f},   {0.74f, 0.74f, 0.13f},
                                   {0.09f, 0.75f, 0.81f}};

struct Decades {
    int low, high;  // floor and ceil of log10 of the data range
};

Decades decades_of(const LogLogPlot& plot, bool x) {
    double lo = INFINITY, hi = -INFINITY;
    for (const PlotSeries& s : plot.series)
        for (const auto& [px, py] : s.points) {
            const double v = x ? px : py;
            if (v > 0 && std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
        }
    if (!(lo <= hi)) return {0, 1};
    const int low = int(std::floor(std::log10(lo))), high = int(std::ceil(std::log10(hi)));
    return {low, std::max(high, low + 1)};
}

std::string decade_label(int exponent) {
    char text[16];
    std::snprintf(text, sizeof text, "1e%d", exponent);
    return text;
}

class Canvas {
public:
    Canvas(int width, int height, const std::string& path)
        : buf_(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT)), path_(path) {
        const float white[3] = {1, 1, 1};
        OIIO::ImageBufAlgo::fill(buf_, white);
    }
    void line(double x0, double y0, double x1, double y1, const float* colour, int thickness = 1) {
        const int steps = int(std::max(std::abs(x1 - x0), std::abs(y1 - y0))) + 1;
        for (int i = 0; i <= steps; ++i) {
            const double t = double(i) / steps;
            const int x = int(std::lround(x0 + t * (x1 - x0))), y = int(std::lround(y0 + t * (y1 - y0)));
            for (int dy = 0; dy < thickness; ++dy)
                for (int dx = 0; dx < thickness; ++dx) buf_.setpixel(x + dx - thickness / 2, y + dy - thickness / 2, colour, 3);
        }
    }
    void text(int x, int y, const std::string& s, int size = 14, const float* colour = kBlack,
              OIIO::ImageBufAlgo::TextAlignX align = OIIO::ImageBufAlgo::TextAlignX::Left) {
        if (!OIIO::ImageBufAlgo::render_text(buf_, x, y, s, size, kFont, {colour, 3}, align))
            throw std::runtime_error(path_ + ": cannot draw plot text (" + buf_.geterror() + "); install fonts-dejavu-core");
    }
    void write() {
        if (!buf_.write(path_, OIIO::TypeDesc::UINT8)) throw std::runtime_error(path_ + ": cannot write the plot: " + buf_.geterror());
    }
    static constexpr float kBlack[3] = {0, 0, 0};

private:
    OIIO::ImageBuf buf_;
    std::string path_;
};

// Tick marks of a linear axis over [low, high]: a step of 1, 2 or 5 times a power of ten, about five of them.
struct LinearAxis {
    double low, high, step;
};

LinearAxis linear_axis(double low, double high) {
    if (!(high > low)) low -= 0.5 * (std::abs(low) + 1.0), high += 0.5 * (std::abs(high) + 1.0);
    const double raw = (high - low) / 5.0, power = std::pow(10.0, std::floor(std::log10(raw)));
    const double step = raw <= power ? power : raw <= 2 * power ? 2 * power : raw <= 5 * power ? 5 * power : 10 * power;
    return {std::floor(low / step) * step, std::ceil(high / step) * step, step};
}

std::string tick_label(double value, double step) {
    char text[32];
    const int decimals = std::max(0, -int(std::floor(std::log10(step))));
    std::snprintf(text, sizeof text, "%.*f", decimals, std::abs(value) < 0.5 * step ? 0.0 : value);
    return text;
}

// The least-squares line y = a + b x through the points, if they are not all at one x.
std::optional<std::pair<double, double>> least_squares(const std::vector<ScatterPoint>& points) {
    double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const ScatterPoint& p : points) n += 1, sx += p.x, sy += p.y, sxx += p.x * p.x, sxy += p.x * p.y;
    const double d = n * sxx - sx * sx;
    if (n < 2 || !(std::abs(d) > 0)) return std::nullopt;
    const double b = (n * sxy - sx * sy) / d;
    return std::pair{(sy - b * sx) / n, b};
}

// Draws the line a + b x where it lies inside the axes' box.
template <class ToX, class ToY>
void draw_fit(Canvas& canvas, std::pair<double, double> fit, const LinearAxis& ax, const LinearAxis& ay, ToX&& px, ToY&& py) {
    const auto [a, b] = fit;
    double from = ax.low, to = ax.high;
    if (b != 0) {
        const double at_low = (ay.low - a) / b, at_high = (ay.high - a) / b;
        from = std::max(from, std::min(at_low, at_high)), to = std::min(to, std::max(at_low, at_high));
    } else if (a < ay.low || a > ay.high) {
        return;
    }
    const float grey[3] = {0.6f, 0.6f, 0.6f};
    if (from < to) canvas.line(px(from), py(a + b * from), px(to), py(a + b * to), grey, 2);
}

void draw_panel(Canvas& canvas, const ScatterPanel& panel, const ScatterPlot& plot, int x0, int panel_width, int height) {
    constexpr int left = 76, right = 28, top = 68, bottom = 56;
    using Align = OIIO::ImageBufAlgo::TextAlignX;
    std::vector<ScatterPoint> points;
    for (const ScatterPoint& p : panel.points)
        if (std::isfinite(p.x) && std::isfinite(p.y)) points.push_back(p);
    double xl = INFINITY, xh = -INFINITY, yl = INFINITY, yh = -INFINITY;
    for (const ScatterPoint& p : points) xl = std::min(xl, p.x), xh = std::max(xh, p.x), yl = std::min(yl, p.y), yh = std::max(yh, p.y);
    if (points.empty()) xl = yl = 0, xh = yh = 1;
    const LinearAxis ax = linear_axis(xl, xh), ay = linear_axis(yl, yh);
    const double plot_w = panel_width - left - right, plot_h = height - top - bottom;
    auto px = [&](double x) { return x0 + left + (x - ax.low) / (ax.high - ax.low) * plot_w; };
    auto py = [&](double y) { return top + plot_h - (y - ay.low) / (ay.high - ay.low) * plot_h; };
    const float grid[3] = {0.88f, 0.88f, 0.88f};
    for (double v = ax.low; v <= ax.high + 0.5 * ax.step; v += ax.step) {
        canvas.line(px(v), top, px(v), top + plot_h, grid);
        canvas.text(int(px(v)), int(top + plot_h + 18), tick_label(v, ax.step), 12, Canvas::kBlack, Align::Center);
    }
    for (double v = ay.low; v <= ay.high + 0.5 * ay.step; v += ay.step) {
        canvas.line(x0 + left, py(v), x0 + left + plot_w, py(v), grid);
        canvas.text(x0 + left - 6, int(py(v)) + 4, tick_label(v, ay.step), 12, Canvas::kBlack, Align::Right);
    }
    canvas.line(x0 + left, top + plot_h, x0 + left + plot_w, top + plot_h, Canvas::kBlack);
    canvas.line(x0 + left, top, x0 + left, top + plot_h, Canvas::kBlack);
    canvas.text(x0 + panel_width / 2, 20, panel.title, 15, Canvas::kBlack, Align::Center);
    canvas.text(x0 + panel_width / 2, 38, panel.subtitle, 12, Canvas::kBlack, Align::Center);
    canvas.text(x0 + left + int(plot_w / 2), height - 12, plot.x_label, 13, Canvas::kBlack, Align::Center);
    canvas.text(x0 + 8, top - 8, plot.y_label, 13);
    if (const auto fit = least_squares(points)) draw_fit(canvas, *fit, ax, ay, px, py);
    for (size_t i = 0; i < points.size(); ++i) {
        const float* colour = kPalette[i % 10];
        canvas.line(px(points[i].x), py(points[i].y), px(points[i].x), py(points[i].y), colour, 7);
        canvas.text(int(px(points[i].x)) + 7, int(py(points[i].y)) - 5, points[i].label, 12, colour);
    }
}

}  // namespace

void write_plot_png(const LogLogPlot& plot, const std::string& path, int width, int height) {
    constexpr int left = 80, right = 260, top = 64, bottom = 60;  // margins: the legend sits on the right
    const Decades dx = decades_of(plot, true), dy = decades_of(plot, false);
    const double plot_w = width - left - right, plot_h = height - top - bottom;
    auto px = [&](double x) { return left + (std::log10(x) - dx.low) / (dx.high - dx.low) * plot_w; };
    auto py = [&](double y) { return top + plot_h - (std::log10(y) - dy.low) / (dy.high - dy.low) * plot_h; };

    Canvas canvas(width, height, path);
    const float grid[3] = {0.85f, 0.85f, 0.85f};
    for (int e = dx.low; e <= dx.high; ++e) {
        canvas.line(px(std::pow(10.0, e)), top, px(std::pow(10.0, e)), top + plot_h, grid);
        canvas.text(int(px(std::pow(10.0, e))), int(top + plot_h + 20), decade_label(e), 13, Canvas::kBlack, OIIO::ImageBufAlgo::TextAlignX::Center);
    }
    for (int e = dy.low; e <= dy.high; ++e) {
        canvas.line(left, py(std::pow(10.0, e)), left + plot_w, py(std::pow(10.0, e)), grid);
        canvas.text(left - 8, int(py(std::pow(10.0, e))) + 5, decade_label(e), 13, Canvas::kBlack, OIIO::ImageBufAlgo::TextAlignX::Right);
    }
    canvas.line(left, top + plot_h, left + plot_w, top + plot_h, Canvas::kBlack);
    canvas.line(left, top, left, top + plot_h, Canvas::kBlack);
    canvas.text(left + int(plot_w / 2), height - 15, plot.x_label, 15, Canvas::kBlack, OIIO::ImageBufAlgo::TextAlignX::Center);
    canvas.text(10, top - 14, plot.y_label, 15);
    canvas.text(left + int(plot_w / 2), 22, plot.title, 17, Canvas::kBlack, OIIO::ImageBufAlgo::TextAlignX::Center);

    for (size_t s = 0; s < plot.series.size(); ++s) {
        const float* colour = kPalette[s % 10];
        const auto& points = plot.series[s].points;
        for (size_t i = 1; i < points.size(); ++i) {
            const auto [x0, y0] = points[i - 1];
            const auto [x1, y1] = points[i];
            if (x0 > 0 && y0 > 0 && x1 > 0 && y1 > 0) canvas.line(px(x0), py(y0), px(x1), py(y1), colour, 2);
        }
        for (const auto& [x, y] : points)
            if (x > 0 && y > 0) canvas.line(px(x) - 2, py(y), px(x) + 2, py(y), colour, 3);
        const int ly = top + 20 + 22 * int(s);
        canvas.line(width - right + 15, ly - 5, width - right + 40, ly - 5, colour, 3);
        canvas.text(width - right + 48, ly, plot.series[s].label, 13);
    }
    canvas.write();
}

void write_scatter_png(const ScatterPlot& plot, const std::string& path, int panel_width, int height) {
    Canvas canvas(panel_width * int(std::max<size_t>(1, plot.panels.size())), height, path);
    for (size_t p = 0; p < plot.panels.size(); ++p) draw_panel(canvas, plot.panels[p], plot, int(p) * panel_width, panel_width, height);
    canvas.write();
}

}  // namespace canopy
