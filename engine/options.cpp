#include "engine/options.h"

#include "accel/builder.h"

#include <algorithm>
#include <stdexcept>

namespace canopy {

std::string builder_names(bool with_auto) {
    std::string names = "a name, or NAME:key=value,key=value with its parameters";
    for (const BuilderName& b : all_builders()) {
        names += "\n  " + b.name + ": " + b.description;
        if (is_bvh_builder(b.name)) names += builder_params_help(find_builder(b.name));
    }
    if (!with_auto) return names;
    return names + "\n  auto: candidates built and timed on a sample of the frame, for --frames-planned";
}

void check_blas_builder(const std::string& blas, const std::vector<std::string>& toplevels) {
    if (blas.empty()) return;
    if (std::none_of(toplevels.begin(), toplevels.end(), [](const std::string& t) { return t != "flat"; }))
        throw std::invalid_argument("--blas-builder " + blas + ": only --toplevel two-level or rebraid has object BVHs");
    if (blas == "auto") throw std::invalid_argument("--blas-builder auto: auto chooses a whole accelerator, not an object BVH builder");
    try {
        find_builder(parse_builder_spec(blas).name);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(std::string("--blas-builder: ") + e.what());
    }
}

Scene load_scene_within_memory(const std::string& name, std::span<const BuildPlan> plans, uint64_t frame_bytes,
                               std::optional<uint64_t> memory_limit, MemoryEstimate* estimate) {
    const MemoryAvailable available = available_memory(memory_limit);
    return load_scene(name, [&](const SceneSize& size) {
        MemoryEstimate e = estimate_memory(size, plans);
        e.process = resident_bytes();
        if (!name.starts_with("gen:")) e.scene = 0;  // a file scene is sized once loaded: the process holds it already
        e.frames = frame_bytes;
        require_memory(name.empty() ? "the default scene" : name, e, available);
        if (estimate) *estimate = e;
    });
}

}  // namespace canopy
