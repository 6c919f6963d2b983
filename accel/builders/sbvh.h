#pragma once
#include "accel/builder.h"

namespace canopy {

// SBVH's alpha (Stich et al. 2009): spatial splits are tried only where the best object split's children overlap by
// more than this share of the root's surface area. Stich et al. and the quality-metrics paper use 1e-5; 1e-3 builds
// in about half the time for frames as fast (docs/results.md#sbvhs-alpha), so canopy's default is 1e-3 and the papers'
// reproductions give "sbvh:alpha=1e-5".
constexpr float kSbvhAlpha = 1e-3f;
// Builder sbvh's parameter, "alpha" (finite and >= 0, default kSbvhAlpha), as its registry entry lists it.
std::vector<BuilderParam> sbvh_params();
// A finite alpha >= 0; throws std::invalid_argument naming `text` otherwise.
float parse_sbvh_alpha(const std::string& text);

struct SbvhSettings {
    // Spatial splits are tried only where the best object split's children overlap by more than alpha times the
    // root's surface area (Stich et al. 2009; kSbvhAlpha says why canopy's default is not their 1e-5).
    float alpha = kSbvhAlpha;
    // Memory cap: at most this many references per triangle in all. Each subtree gets a share of the spare slots
    // in proportion to its references and splits only within it, so the tree does not depend on thread timing;
    // where the share is used up only object splits remain. 2 bounds the reference array at twice binned SAH's,
    // above the 20-50% increase SBVH makes on typical scenes (Ganestam and Doggett 2016, Table 3).
    float max_references_per_triangle = 2.0f;
    // Triangles a leaf test is charged per, whatever the kernel's block: 1, so that leaves of a few triangles
    // split on where their boxes shrink (spatially, down to single triangles), and the wide layout's collapse
    // groups the pieces back into full blocks by its own cost (README, split builders).
    uint32_t leaf_block = 1;
};

// Split BVH (Stich, Friedrich and Dietrich 2009): top-down, at each node the cheaper of the best binned object
// split and the best binned spatial split on any axis, whose straddling references are clipped to the plane
// (exact bounds, accel/triangle_clipping.h) or kept whole on one side where that is cheaper (Stich et al.'s
// reference unsplitting).
// Parallel over subtrees; the tree does not depend on the number of threads.
Bvh build_sbvh_with(BuildInput&& input, const BuildSettings& settings, const SbvhSettings& sbvh);
Bvh build_sbvh(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
