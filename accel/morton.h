#pragma once
// Morton order of references (Lauterbach et al. 2009): 63-bit codes of the centroids within their bounds,
// sorted by a parallel, stable radix sort. Shared by the builders that start from a space-filling curve.
#include "base/geometry.h"

#include <cstdint>
#include <vector>

namespace canopy {

struct MortonOrder {
    std::vector<uint64_t> codes;  // sorted
    std::vector<uint32_t> order;  // order[i]: the reference with the i-th code; equal codes in index order
    BBox bounds;                  // of the references' boxes, found in the same pass as the centroids' box
};

MortonOrder sort_by_morton_code(const std::vector<PrimRef>& refs);

}  // namespace canopy
