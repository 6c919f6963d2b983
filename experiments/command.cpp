#include "experiments/command.h"
#include "renderer/path_tracer.h"

#include <CLI/CLI.hpp>

#include <cstdlib>

namespace canopy {

namespace {

// The number that `text` starts with must be above zero: a bound of zero refuses every scene, and a negative one,
// read as an unsigned size, wraps round to a bound no scene reaches, turning the guard off. Text that starts with
// no number is left for the size's own reading to refuse.
std::string positive_or_not_a_number(std::string& text) {
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    return end == text.c_str() || value > 0 ? "" : "must be above zero, as 512M or 16G; not " + text;
}

}  // namespace

void add_memory_limit_option(CLI::App& command, std::optional<uint64_t>& bytes) {
    command.add_option("--memory-limit", bytes,
                       "Refuse scenes whose estimated peak memory (scene, PrimRefs, trees) exceeds these bytes (suffixes k, "
                       "M, G: powers of 1024); the bound is otherwise the memory the machine and its cgroup have available")
        ->transform(CLI::AsSizeValue(false))
        // A transform goes ahead of those added before it: this one sees the text as typed, before its reading as a size.
        ->transform(CLI::Validator(positive_or_not_a_number, ""));
}

void WorkloadOptions::apply(FrameSettings& settings) const {
    settings.workload = parse_workload(workload);
    settings.ao_rays = ao_rays;
    settings.ao_length = ao_length;
}

void add_workload_options(CLI::App& command, WorkloadOptions& options) {
    command.add_option("--workload", options.workload, kWorkloadHelp)
        ->check(CLI::IsMember({"diffuse", "camera", "nee", "ao"}))
        ->capture_default_str();
    command.add_option("--ao-rays", options.ao_rays, "ao: occlusion rays from each camera hit")
        ->check(CLI::Range(1, 1024))
        ->capture_default_str();
    command.add_option("--ao-length", options.ao_length, "ao: the occlusion rays' length (default: a tenth of the scene box's diagonal)")
        ->check(CLI::PositiveNumber);
}

}  // namespace canopy
