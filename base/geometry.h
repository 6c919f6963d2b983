#pragma once
// Small value types shared by every module: triangles, boxes, primitive references.
#include <glm/vec3.hpp>
#include <glm/geometric.hpp>
#include <algorithm>
#include <cstdint>
#include <limits>

namespace canopy {

using Vec3 = glm::vec3;

struct Triangle {
    Vec3 v0, v1, v2;
};

inline Vec3 geometric_normal(const Triangle& t) { return glm::cross(t.v1 - t.v0, t.v2 - t.v0); }
inline float triangle_area(const Triangle& t) { return 0.5f * glm::length(geometric_normal(t)); }

struct BBox {
    Vec3 lower{std::numeric_limits<float>::infinity()};
    Vec3 upper{-std::numeric_limits<float>::infinity()};

    static BBox of(const Triangle& t) {
        return {glm::min(t.v0, glm::min(t.v1, t.v2)), glm::max(t.v0, glm::max(t.v1, t.v2))};
    }
    bool empty() const { return lower.x > upper.x || lower.y > upper.y || lower.z > upper.z; }
    bool contains(const Vec3& p) const {  // false for a NaN coordinate
        return p.x >= lower.x && p.y >= lower.y && p.z >= lower.z && p.x <= upper.x && p.y <= upper.y && p.z <= upper.z;
    }
    void extend(const BBox& b) { lower = glm::min(lower, b.lower); upper = glm::max(upper, b.upper); }
    void extend(const Vec3& p) { lower = glm::min(lower, p); upper = glm::max(upper, p); }
    Vec3 extent() const { return upper - lower; }
    Vec3 center() const { return 0.5f * (lower + upper); }
    float half_area() const {
        if (empty()) return 0.0f;
        const Vec3 e = extent();
        return e.x * e.y + e.y * e.z + e.z * e.x;
    }
    float area() const { return 2.0f * half_area(); }
    int largest_axis() const {
        const Vec3 e = extent();
        return e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    }
};

inline BBox merge(BBox a, const BBox& b) { a.extend(b); return a; }

// A builder's input item: the bounds of (a piece of) one triangle and that triangle's index.
// Split builders emit several PrimRefs for one triangle, each with the bounds of its piece.
struct alignas(32) PrimRef {
    Vec3 lower;
    uint32_t prim;
    Vec3 upper;
    uint32_t reserved = 0;  // keeps the type at 32 bytes; split builders may tag references here

    BBox bounds() const { return {lower, upper}; }
    Vec3 center2() const { return lower + upper; }  // twice the centroid: saves a multiply in binning
};
static_assert(sizeof(PrimRef) == 32);

}  // namespace canopy
