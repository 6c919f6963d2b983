#include "accel/builder.h"
#include "accel/binned_sah.h"
#include "accel/bonsai.h"
#include "accel/lbvh.h"
#include "accel/sweep_sah.h"

#include <stdexcept>

namespace canopy {

const std::vector<BuilderEntry>& builders() {
    static const std::vector<BuilderEntry> registry = {
        {"binned", "parallel binned SAH (Wald 2007), leaves by SAH termination", &build_binned_sah},
        {"lbvh", "linear BVH: Morton codes, radix sort, Karras 2012 hierarchy; one triangle per leaf", &build_lbvh},
        {"sweep", "full sweep SAH (MacDonald and Booth 1990), leaves by SAH termination", &build_sweep_sah},
        {"bonsai", "Bonsai (Ganestam et al. 2015): mid-point partitions, sweep SAH mini-trees, pruning, sweep SAH top tree",
         &build_bonsai},
        {"bonsai-split", "BONSAIS (Ganestam and Doggett 2016): Bonsai with SAH-guided split partitioning", &build_bonsai_split},
        {"sweep-presplit", "SWEEPPRE (Ganestam and Doggett 2016): split partitioning as a pre-split pass, then sweep SAH",
         &build_sweep_presplit},
    };
    return registry;
}

const BuilderEntry& find_builder(const std::string& name) {
    std::string known;
    for (const BuilderEntry& entry : builders()) {
        if (entry.name == name) return entry;
        known += (known.empty() ? "" : ", ") + entry.name;
    }
    throw std::invalid_argument("unknown builder '" + name + "' (known: " + known + ")");
}

Bvh build_start_tree(BuildInput&& input, const BuildSettings& settings, const char* default_start) {
    BuildSettings start_settings = settings;
    start_settings.start.clear();
    return find_builder(settings.start.empty() ? default_start : settings.start).build(std::move(input), start_settings);
}

}  // namespace canopy
