#pragma once
// Option checks and scene set-up that every command shares: builder names, the two-level builder's checks, and a
// scene loaded within the memory its planned builds need.
#include "accel/memory_budget.h"
#include "scenes/scene.h"

#include <optional>
#include <span>
#include <string>
#include <vector>

namespace canopy {

// Every registered builder's name, for the options' help; `with_auto` adds auto, for the commands that render frames
// it can time its candidates on.
std::string builder_names(bool with_auto = true);
// --blas-builder names the object trees' builder, which only two-level top levels have.
void check_blas_builder(const std::string& blas, const std::vector<std::string>& toplevels);

// load_scene, refused with a MemoryError when the scene, the planned builds and `frame_bytes` (images and the stream
// tracer's batches) would not fit in the memory available (accel/memory_budget.h): a generator spec before it
// generates anything, a file before flatten(). `estimate`, when given, receives the estimate the scene was admitted
// with.
Scene load_scene_within_memory(const std::string& name, std::span<const BuildPlan> plans, uint64_t frame_bytes,
                               std::optional<uint64_t> memory_limit, MemoryEstimate* estimate = nullptr);

}  // namespace canopy
