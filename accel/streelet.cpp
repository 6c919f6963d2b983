#include "accel/streelet.h"

#include "accel/lbvh.h"
#include "accel/presplit.h"
#include "accel/treelet_restructuring.h"

#include <chrono>

namespace canopy {

// The quality-metrics paper runs STreelet with a 30% split quota in all but one scene.
constexpr float kStreeletSplitQuota = 0.3f;

Bvh build_streelet(BuildInput&& input, const BuildSettings& settings) {
    const auto start = std::chrono::steady_clock::now();
    input.refs = presplit_refs(input.triangles, std::move(input.refs), kStreeletSplitQuota);
    const double split_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const uint64_t capacity = input.refs.capacity();
    Bvh bvh = build_lbvh(std::move(input), settings);
    optimise_treelets(bvh, settings);
    bvh.split = {split_ms, capacity};
    return bvh;
}

}  // namespace canopy
