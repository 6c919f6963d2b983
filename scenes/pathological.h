#pragma once
// Triangle soups that push builders to their worst cases: identical triangles, one plane, zero-area triangles,
// parallel needles and a box scaled far from unit size. The suite checks every builder on them
// (tests/test_pathological.cpp) and tools/pathological_builds times every builder on them at a million triangles.
#include "base/geometry.h"

#include <cstddef>
#include <string>
#include <vector>

namespace canopy {

struct PathologicalScene {
    std::string name;
    std::vector<Triangle> (*make)(size_t triangles);
};

// Uniformly placed triangles of random orientation (gen:triangles): the yardstick the others are timed against.
std::vector<Triangle> random_triangles(size_t n);
std::vector<Triangle> identical_triangles(size_t n);
// Small triangles scattered over the square [-1, 1]^2 of the plane z = 0, overlapping at random.
std::vector<Triangle> triangles_in_one_plane(size_t n);
// Collinear triangles (the third corner on the first edge's line) and points, scattered in [-1, 1]^3.
std::vector<Triangle> zero_area_triangles(size_t n);
// Long, thin triangles, all along the diagonal (1, 1, 1): their boxes are cubes that they barely fill, which
// makes the split builders split them hardest.
std::vector<Triangle> parallel_needles(size_t n);
// gen:box's triangles, every coordinate multiplied by `scale`, without flatten()'s refusal of extreme scales.
std::vector<Triangle> scaled_box(size_t n, float scale);

// Every scene above but the yardstick, the box at 1e-30 and at 1e30.
const std::vector<PathologicalScene>& pathological_scenes();

}  // namespace canopy
