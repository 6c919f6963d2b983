#pragma once
#include "accel/builder.h"

#include <span>
#include <vector>

namespace canopy {

struct PresplitSettings {
    float budget = 0.5f;  // extra references, as a fraction of the triangle count (Karras and Aila 2013 sec. 5)
};

// Budgeted pre-splitting (Karras and Aila 2013, "Fast parallel construction of high-quality BVHs", sec. 5):
// each triangle gets a priority from how much its box exceeds its ideal bounds and how important the grid plane
// it crosses is; the budget (floor(budget_fraction * triangles) extra references) is shared in proportion to
// that priority, and each triangle is split recursively at the most important power-of-two grid plane of the
// scene box. Returns the grown references, each with the exact bounds of its piece; deterministic.
std::vector<PrimRef> presplit_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float budget_fraction);

// presplit_refs, then binned SAH (accel/binned_sah.h) on the grown references.
Bvh build_presplit_with(BuildInput&& input, const BuildSettings& settings, const PresplitSettings& presplit);
Bvh build_presplit(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
