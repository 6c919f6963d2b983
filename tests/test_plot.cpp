// The study's scatter plot: panels side by side, each point drawn in its colour where its axes put it, with text.
#include "experiments/plot.h"

#include <catch2/catch.hpp>
#include <OpenImageIO/imagebuf.h>

#include <filesystem>

using namespace canopy;

namespace {

bool near_colour(const OIIO::ImageBuf& image, int x, int y, float r, float g, float b) {
    float pixel[3];
    image.getpixel(x, y, pixel, 3);
    return std::abs(pixel[0] - r) < 0.02f && std::abs(pixel[1] - g) < 0.02f && std::abs(pixel[2] - b) < 0.02f;
}

// Pixels darker than mid grey in the rows [y0, y1) of the columns [x0, x1): where text was drawn.
int dark_pixels(const OIIO::ImageBuf& image, int x0, int x1, int y0, int y1) {
    int dark = 0;
    float pixel[3];
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) image.getpixel(x, y, pixel, 3), dark += pixel[0] + pixel[1] + pixel[2] < 1.5f;
    return dark;
}

}  // namespace

TEST_CASE("a scatter plot draws a panel per scene, its points where its axes put them, and its titles", "[plot]") {
    const std::string path = (std::filesystem::temp_directory_path() / "canopy_test_scatter.png").string();
    // Ticks 0..10 on both axes: the point (10, 10) sits at the top-right corner of the first panel's axes.
    const ScatterPlot plot{"predicted", "measured",
                           {{"scene one", "fit", {{0.0, 0.0, "a"}, {10.0, 10.0, "b"}, {5.0, NAN, "skipped"}}},
                            {"scene two", "fit", {{1.0, 3.0, "c"}, {2.0, 1.0, "d"}}}}};
    write_scatter_png(plot, path, 400, 400);
    const OIIO::ImageBuf image(path);
    REQUIRE(image.spec().width == 800);
    REQUIRE(image.spec().height == 400);
    // The panel's axes run from x = 76 to 400 - 28 and from y = 68 to 400 - 56 (plot.cpp's margins).
    CHECK(near_colour(image, 76, 400 - 56 - 1, 0.12f, 0.47f, 0.71f));   // "a", the palette's first colour
    CHECK(near_colour(image, 400 - 28 - 1, 68 + 1, 1.0f, 0.5f, 0.05f));  // "b", the second
    CHECK(dark_pixels(image, 0, 400, 0, 30) > 20);                       // "scene one"
    CHECK(dark_pixels(image, 400, 800, 0, 30) > 20);                     // "scene two"
    CHECK(dark_pixels(image, 76, 372, 400 - 20, 400) > 20);              // the x axis's label
    std::filesystem::remove(path);
}
