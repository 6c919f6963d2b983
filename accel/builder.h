#pragma once
// The builder interface and the registry that chooses builders by name at run time.
// Adding a builder: one file with its build function, one line in registry.cpp.
#include "accel/bvh.h"

#include <span>
#include <string>
#include <vector>

namespace canopy {

struct BuildInput {
    std::span<const Triangle> triangles;  // split builders clip these; others only read refs
    std::vector<PrimRef> refs;            // one per triangle on entry; the builder may reorder or grow it
};

// Early split clipping's surface-area limit, SA_max of Ernst and Greiner 2007 (Algorithm 4), for builder "esc":
// automatic (early_split_clipping.h), an absolute box area in scene units (the paper's), or a multiple of the
// scene's median ideal triangle area (Karras and Aila 2013, sec. 5), which means the same on scenes of any scale.
struct SaMax {
    enum class Unit { Automatic, Absolute, MedianIdealArea };
    Unit unit = Unit::Automatic;
    float value = 0.0f;  // > 0 and finite unless automatic

    bool operator==(const SaMax&) const = default;
};
// "auto", "12.5" (absolute) or "8x" (median ideal areas); throws std::invalid_argument naming `text` otherwise.
SaMax parse_sa_max(const std::string& text);
std::string sa_max_name(const SaMax& sa_max);  // parse_sa_max's inverse

// SBVH's alpha (Stich et al. 2009), builder "sbvh": spatial splits are tried only where the best object split's
// children overlap by more than this share of the root's surface area. Stich et al. and the quality-metrics paper
// use 1e-5; at 1e-3 sbvh bvh8 built crytek-sponza, sibenik and conference in 0.54x, 0.57x and 0.78x the time, its
// frames as fast (docs/results.md), so canopy's default is 1e-3 and the papers' reproductions set 1e-5.
constexpr float kSbvhAlpha = 1e-3f;
constexpr float kPapersSbvhAlpha = 1e-5f;

struct BuildSettings {
    SahCosts costs;
    uint32_t max_leaf_size = 8;  // a leaf is split above this even when SAH prefers a leaf
    uint32_t bins = 32;          // binned builders
    // Triangles the kernel tests at once (1 scalar, 4 SIMD; a power of two): the SAH charges a leaf of n triangles
    // for ceil(n / leaf_block) tests, so SIMD kernels get leaves that fill their lanes.
    uint32_t leaf_block = 1;
    // Optimisers restructure a tree built by another builder: this one, or the optimiser's default if empty.
    std::string start;
    SaMax esc_sa_max;  // builder "esc" only
    float sbvh_alpha = kSbvhAlpha;  // builder "sbvh" only

    float leaf_tests(uint32_t n) const { return float((n + leaf_block - 1) / leaf_block); }
};

using BuildFunction = Bvh (*)(BuildInput&&, const BuildSettings&);

struct BuilderEntry {
    std::string name;
    std::string description;
    BuildFunction build;
    const char* default_start = nullptr;  // set for optimisers: the builder of their start tree
};

const std::vector<BuilderEntry>& builders();
// Throws InputError-like std::invalid_argument listing the known names when `name` is unknown, or saying what
// `name` builds when it names another structure family.
const BuilderEntry& find_builder(const std::string& name);

// Acceleration structures other than the BVH (the kd-tree), each built and traced by an accelerator of its own
// (make_canopy_accelerator routes their names there). A third family is a line here and a line there.
struct FamilyEntry {
    std::string name, description;
    std::string structure;  // what it builds, for errors: "kd-tree"
};
const std::vector<FamilyEntry>& other_families();

// Every name `--builder` takes, with its description: builders(), then other_families().
struct BuilderName {
    std::string name, description;
};
std::vector<BuilderName> all_builders();
bool is_bvh_builder(const std::string& name);
// Throws std::invalid_argument listing every name when `name` is neither a BVH builder nor another family.
void check_builder_name(const std::string& name);

// The start tree of an optimiser: built by settings.start, or by `default_start` when that is empty. The start
// builder sees the same settings with no start of its own, so optimisers chain but never recurse.
Bvh build_start_tree(BuildInput&& input, const BuildSettings& settings, const char* default_start);

// One PrimRef per triangle, in parallel. Degenerate triangles keep their (flat) boxes;
// triangles with non-finite vertices are rejected by the scene loaders before this point.
std::vector<PrimRef> make_prim_refs(std::span<const Triangle> triangles);

}  // namespace canopy
