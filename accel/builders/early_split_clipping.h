#pragma once
#include "accel/builder.h"

#include <cmath>
#include <span>
#include <string>
#include <vector>

namespace canopy {

// Algorithm 4 of Ernst and Greiner 2007: a triangle's box is halved at the centre of its largest axis, each half
// clipped to the triangle, until every piece's box has a surface area of at most `sa_max`. A triangle is cut
// into at most 2^kMaxEscDepth pieces (boxes too small for float halving stop early). Deterministic.
constexpr int kMaxEscDepth = 10;
// When the pieces would number more than max_references, SA_max doubles until they do not (build_esc passes
// kMaxEscReferencesPerTriangle times the triangles: long needles across a scene would otherwise each become
// 2^kMaxEscDepth pieces, gigabytes of references from a scene of megabytes).
std::vector<PrimRef> early_split_clip_refs(std::span<const Triangle> triangles, std::vector<PrimRef>&& refs, float sa_max,
                                           uint64_t max_references = UINT64_MAX);
constexpr double kMaxEscReferencesPerTriangle = 4.0;
// Triangles whose edges meet at a sine of at most kEscLineSine stay whole at any SA_max: lines and points, or
// slivers nearly as thin, which rays seldom or never hit, so that a scene of them does not spend the reference
// budget where it buys nothing (docs/results.md#pathological-scenes-at-a-million-triangles).
constexpr float kEscLineSine = 1e-5f;
bool esc_keeps_whole(const Triangle& t);
// The references early_split_clip_refs would make at this SA_max, with no cap: without making them.
uint64_t early_split_clip_count(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, float sa_max);

// The automatic SA_max; Ernst and Greiner leave its choice open. Splitting pays where triangles' boxes are
// mostly empty (slivers across the axes), and hurts where large boxes hold large, well-filled triangles (walls,
// floors: their pieces mix into subtrees of other geometry and inflate them). So, with A_ideal the box area of a
// triangle cut into infinitely fine pieces (twice its projected areas, Karras and Aila 2013 sec. 5):
//   fill = sum A_ideal / sum A_box over the scene;
//   fill >= 0.1 (boxes on the whole at most ten times what their triangles need): no splitting, SA_max = infinity;
//   otherwise SA_max = 8 median(A_ideal): pieces are cut until a typical triangle's box is filled to an eighth,
//   which on a sliver field buys a much faster frame for more references
//   (docs/results.md#split-builders-on-a-sliver-field).
// Measured fills: every scene in ../shared/scenes, gen:surface, gen:box, gen:triangles 0.31-0.48; gen:cylinders 0.03.
// Returns infinity for no splitting.
float automatic_sa_max(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs);
constexpr double kEscMaxFillToSplit = 0.1;  // the fill from which the automatic SA_max splits nothing

// A_ideal of Karras and Aila 2013 (sec. 5): the summed box areas of infinitely fine pieces of the triangle,
// twice its projected area on the three axis planes.
inline float ideal_area(const Triangle& t) {
    const Vec3 n = geometric_normal(t);
    return std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
}

// Early split clipping's surface-area limit, SA_max of Ernst and Greiner 2007 (Algorithm 4): automatic (above), an
// absolute box area in scene units (the paper's), or a multiple of the scene's median ideal triangle area (Karras
// and Aila 2013, sec. 5), which means the same on scenes of any scale.
struct SaMax {
    enum class Unit { Automatic, Absolute, MedianIdealArea };
    Unit unit = Unit::Automatic;
    float value = 0.0f;  // > 0 and finite unless automatic

    bool operator==(const SaMax&) const = default;
};
// "auto", "12.5" (absolute) or "8x" (median ideal areas); throws std::invalid_argument naming `text` otherwise.
SaMax parse_sa_max(const std::string& text);
std::string sa_max_name(const SaMax& sa_max);  // parse_sa_max's inverse

// Builder esc's parameter, "sa_max" (parse_sa_max's texts, default auto), as its registry entry lists it.
constexpr const char* kEscSaMaxKey = "sa_max";
std::vector<BuilderParam> esc_params();
// The SA_max a build of esc with these settings uses (the automatic one when the settings give none).
SaMax esc_sa_max(const BuildSettings& settings);

// `sa_max` in box area units for this scene: infinity for no splitting. Throws std::invalid_argument for a value
// that is not finite and positive.
float resolve_esc_area(std::span<const Triangle> triangles, const std::vector<PrimRef>& refs, const SaMax& sa_max);

// early_split_clip_refs at esc_sa_max(settings) within kMaxEscReferencesPerTriangle, then binned SAH
// (accel/binned_sah.h) on the grown references.
Bvh build_esc(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
