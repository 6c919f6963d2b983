#pragma once
// Pinhole camera exactly as ../shared/BENCHMARK.md "The frame" defines it.
#include "kernels/ray.h"
#include "scenes/scene.h"

#include <cmath>

namespace canopy {

class PinholeCamera {
public:
    PinholeCamera(const Camera& c, int width, int height)
        : eye_(c.eye), width_(float(width)), height_(float(height)) {
        forward_ = glm::normalize(c.target - c.eye);
        right_ = glm::normalize(glm::cross(forward_, c.up));
        up_ = glm::cross(right_, forward_);
        tan_half_fov_ = std::tan(0.5f * c.fov_deg * 3.14159265358979f / 180.0f);
        aspect_ = width_ / height_;
    }

    // Pixel (x, y), row 0 at the top, jittered by (u, v) in [0, 1).
    Ray generate(int x, int y, float u, float v) const {
        const float sx = (2.0f * (float(x) + u) / width_ - 1.0f) * tan_half_fov_ * aspect_;
        const float sy = (1.0f - 2.0f * (float(y) + v) / height_) * tan_half_fov_;
        return {eye_, glm::normalize(forward_ + sx * right_ + sy * up_)};
    }

private:
    Vec3 eye_, forward_, right_, up_;
    float width_, height_, tan_half_fov_, aspect_;
};

}  // namespace canopy
