#include "accel/builder.h"
#include "accel/binned_sah.h"
#include "accel/early_split_clipping.h"
#include "accel/lbvh.h"
#include "accel/presplit.h"
#include "accel/sbvh.h"
#include "accel/sweep_sah.h"

#include <stdexcept>

namespace canopy {

const std::vector<BuilderEntry>& builders() {
    static const std::vector<BuilderEntry> registry = {
        {"binned", "parallel binned SAH (Wald 2007), leaves by SAH termination", &build_binned_sah},
        {"lbvh", "linear BVH: Morton codes, radix sort, Karras 2012 hierarchy; one triangle per leaf", &build_lbvh},
        {"sbvh", "split BVH (Stich et al. 2009): binned object and spatial splits, reference unsplitting, 2x reference cap", &build_sbvh},
        {"presplit", "budgeted pre-splitting (Karras and Aila 2013), 50% budget, then binned SAH", &build_presplit},
        {"esc", "early split clipping (Ernst and Greiner 2007) with automatic SA_max, then binned SAH", &build_esc},
        {"sweep", "full sweep SAH (MacDonald and Booth 1990), leaves by SAH termination", &build_sweep_sah},
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
