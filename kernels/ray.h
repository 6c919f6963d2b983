#pragma once
#include "base/geometry.h"

#include <cstdint>
#include <limits>

namespace canopy {

struct Ray {
    Vec3 org;
    Vec3 dir;
    float tmin = 0.0f;
    float tmax = std::numeric_limits<float>::infinity();
};

struct Hit {
    static constexpr uint32_t kNone = 0xffffffffu;
    float t = std::numeric_limits<float>::infinity();
    float u = 0, v = 0;  // barycentric weights of v1 and v2
    uint32_t prim = kNone;

    bool found() const { return prim != kNone; }
};

}  // namespace canopy
