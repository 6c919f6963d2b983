#pragma once
#include "accel/builder.h"

#include <span>
#include <vector>

namespace canopy {

struct EscSettings {
    float sa_max = 0.0f;  // surface-area limit of a reference's box (full area, BBox::area); 0 chooses it automatically
};

// Algorithm 4 of Ernst and Greiner 2007: a triangle's box is halved at the centre of its largest axis, each half
// clipped to the triangle, until every piece's box has a surface area of at most `sa_max`. A triangle is cut
// into at most 2^kMaxEscDepth pieces (boxes too small for float halving stop early). Deterministic.
constexpr int kMaxEscDepth = 10;
std::vector<PrimRef> early_split_clip_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float sa_max);

// The automatic SA_max (the paper leaves its choice open, sec. 5): see early_split_clipping.cpp.
float automatic_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs);

// early_split_clip_refs, then binned SAH (accel/binned_sah.h) on the grown references.
Bvh build_esc_with(BuildInput&& input, const BuildSettings& settings, const EscSettings& esc);
Bvh build_esc(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
