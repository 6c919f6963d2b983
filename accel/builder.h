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

struct BuildSettings {
    SahCosts costs;
    uint32_t max_leaf_size = 8;  // a leaf is split above this even when SAH prefers a leaf
    uint32_t bins = 32;          // binned builders
    // Triangles the kernel tests at once (1 scalar, 4 SIMD): the SAH charges a leaf of n triangles for
    // ceil(n / leaf_block) tests, so SIMD kernels get leaves that fill their lanes.
    uint32_t leaf_block = 1;

    float leaf_tests(uint32_t n) const { return float((n + leaf_block - 1) / leaf_block); }
};

using BuildFunction = Bvh (*)(BuildInput&&, const BuildSettings&);

struct BuilderEntry {
    std::string name;
    std::string description;
    BuildFunction build;
};

const std::vector<BuilderEntry>& builders();
// Throws InputError-like std::invalid_argument listing the known names when `name` is unknown.
const BuilderEntry& find_builder(const std::string& name);

// One PrimRef per triangle, in parallel. Degenerate triangles keep their (flat) boxes;
// triangles with non-finite vertices are rejected by the scene loaders before this point.
std::vector<PrimRef> make_prim_refs(std::span<const Triangle> triangles);

}  // namespace canopy
