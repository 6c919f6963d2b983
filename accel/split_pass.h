#pragma once
// Builders that split references in a pass of their own before building (presplit, esc, streelet): the pass is
// timed as the split pass, and the reference memory it allocated is reported, for the bench's split columns.
#include "accel/builder.h"

#include <chrono>

namespace canopy {

// split(triangles, refs) returns the grown references; build then builds over them.
template <class SplitPass>
Bvh build_after_split_pass(BuildInput&& input, const BuildSettings& settings, SplitPass&& split, BuildFunction build) {
    const auto start = std::chrono::steady_clock::now();
    input.refs = split(input.triangles, std::move(input.refs));
    const double split_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const uint64_t capacity = input.refs.capacity();
    Bvh bvh = build(std::move(input), settings);
    bvh.split = {split_ms, capacity};
    return bvh;
}

}  // namespace canopy
