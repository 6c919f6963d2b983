// Builds and frames against scene size: reads the JSON of `canopy bench` runs (one scene each, canopy's rows and an
// Embree row) and draws canopy's and Embree's build and frame times against the scene's triangles, log-log.
// Usage: scale_plot OUT.png BENCH.json...
#include "experiments/plot.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <stdexcept>

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: scale_plot OUT.png BENCH.json...\n");
        return 2;
    }
    try {
        canopy::LogLogPlot plot{"builds and frames against scene size (canopy binned bvh8, Embree MEDIUM)", "triangles",
                                "milliseconds (build: the least of the builds; frame: the mean)", {}};
        canopy::PlotSeries build_canopy{"canopy build", {}}, build_embree{"Embree build", {}};
        canopy::PlotSeries frame_canopy{"canopy frame", {}}, frame_embree{"Embree frame", {}};
        for (int i = 2; i < argc; ++i) {
            std::ifstream in(argv[i]);
            if (!in) throw std::runtime_error(std::string(argv[i]) + ": cannot open");
            const nlohmann::json bench = nlohmann::json::parse(in);
            const double tris = bench.at("tris").get<double>();
            for (const nlohmann::json& row : bench.at("results")) {
                if (row.at("tracer") != "single") continue;
                const bool canopy = row.at("accel") == "canopy";
                (canopy ? build_canopy : build_embree).points.push_back({tris, row.at("build_ms_min").get<double>()});
                (canopy ? frame_canopy : frame_embree).points.push_back({tris, row.at("frame_ms_mean").get<double>()});
            }
        }
        plot.series = {build_canopy, build_embree, frame_canopy, frame_embree};
        for (canopy::PlotSeries& series : plot.series) std::sort(series.points.begin(), series.points.end());  // lines left to right
        canopy::write_plot_png(plot, argv[1]);
        std::printf("wrote %s\n", argv[1]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "scale_plot: %s\n", e.what());
        return 1;
    }
}
