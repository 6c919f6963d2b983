#pragma once
// A progress bar on stderr for long renders and studies.
#include <cstdio>

namespace canopy {

// Draws the bar at `fraction` in [0, 1], over the previous one.
inline void print_progress(float fraction) {
    const int width = 40, filled = int(fraction * float(width) + 0.5f);
    std::fprintf(stderr, "\r[%.*s%*s] %3d%%", filled, "========================================", width - filled, "",
                 int(fraction * 100.0f + 0.5f));
}

}  // namespace canopy
