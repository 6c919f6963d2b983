#pragma once
// The order in which a batch of rays is traced: rays of one direction octant together, and within an octant by a
// Morton code of the origin in the scene's box, so that rays traced one after another start near each other and
// head the same way (the sort keys of ray-stream tracers, e.g. Pharr et al. 1997's and Garanzha and Loop 2010's
// origin and direction cells, reduced to what one radix pass per 10 bits can sort).
#include "base/geometry.h"
#include "kernels/ray.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace canopy {

// 3 bits of octant above 27 bits of origin Morton code (9 bits an axis). Origins outside `bounds`, and NaN ones,
// are clamped into it: the key only orders, it never decides a hit.
class RayOrderKey {
public:
    explicit RayOrderKey(const BBox& bounds) : lower_(bounds.lower) {
        const Vec3 extent = bounds.upper - bounds.lower;
        for (int a = 0; a < 3; ++a) scale_[a] = extent[a] > 0.0f ? float(kCells) / extent[a] : 0.0f;
    }

    uint32_t operator()(const Ray& ray) const {
        const uint32_t octant = uint32_t(ray.dir.x < 0.0f) | uint32_t(ray.dir.y < 0.0f) << 1 | uint32_t(ray.dir.z < 0.0f) << 2;
        uint32_t code = 0;
        for (int a = 0; a < 3; ++a) code |= spread(cell((ray.org[a] - lower_[a]) * scale_[a])) << a;
        return octant << 27 | code;
    }

    static constexpr int kBits = 30;

private:
    static constexpr uint32_t kCells = 512;

    static uint32_t cell(float x) { return x >= 0.0f ? uint32_t(std::min(x, float(kCells - 1))) : 0u; }  // NaN: 0
    // The 9 bits of x at every third bit.
    static uint32_t spread(uint32_t x) {
        x = (x | x << 16) & 0x030000ffu;
        x = (x | x << 8) & 0x0300f00fu;
        x = (x | x << 4) & 0x030c30c3u;
        return (x | x << 2) & 0x09249249u;
    }

    Vec3 lower_;
    Vec3 scale_;
};

// A stable least-significant-digit radix sort of `keys` (values below 2^30), giving the permutation `order`:
// order[i] is the index of the i-th smallest key. Three passes of 10 bits; `scratch` is reused between calls.
inline void radix_order(std::span<const uint32_t> keys, std::vector<uint32_t>& order, std::vector<uint32_t>& scratch) {
    constexpr int kDigit = 10, kBuckets = 1 << kDigit, kPasses = (RayOrderKey::kBits + kDigit - 1) / kDigit;
    const size_t n = keys.size();
    order.resize(n);
    scratch.resize(n);
    for (size_t i = 0; i < n; ++i) order[i] = uint32_t(i);
    for (int pass = 0; pass < kPasses; ++pass) {
        const int shift = pass * kDigit;
        std::array<uint32_t, kBuckets> start{};
        for (size_t i = 0; i < n; ++i) ++start[keys[i] >> shift & (kBuckets - 1)];
        uint32_t sum = 0;
        for (uint32_t& s : start) sum += std::exchange(s, sum);
        for (size_t i = 0; i < n; ++i) {
            const uint32_t index = order[i];
            scratch[start[keys[index] >> shift & (kBuckets - 1)]++] = index;
        }
        order.swap(scratch);
    }
}

}  // namespace canopy
