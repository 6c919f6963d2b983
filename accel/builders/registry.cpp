#include "accel/builder.h"
#include "accel/builders/agglomerative.h"
#include "accel/builders/binned_sah.h"
#include "accel/builders/bittner_reinsertion.h"
#include "accel/builders/bonsai.h"
#include "accel/builders/early_split_clipping.h"
#include "accel/builders/lbvh.h"
#include "accel/builders/lbvh_sah.h"
#include "accel/builders/ploc.h"
#include "accel/builders/presplit.h"
#include "accel/builders/sbvh.h"
#include "accel/builders/sweep_sah.h"
#include "accel/builders/streelet.h"
#include "accel/builders/tree_rotations.h"
#include "accel/builders/treelet_restructuring.h"
#include "accel/kdtree.h"

#include <algorithm>
#include <stdexcept>

namespace canopy {

const std::vector<BuilderEntry>& builders() {
    static const std::vector<BuilderEntry> registry = {
        {"agglo", "agglomerative clustering (Walter et al. 2008): closest pair by merged box area; one triangle per leaf",
         &build_agglomerative},
        {"binned", "parallel binned SAH (Wald 2007), leaves by SAH termination", &build_binned_sah},
        {"lbvh", "linear BVH: Morton codes, radix sort, Karras 2012 hierarchy; one triangle per leaf", &build_lbvh},
        {"lbvh-sah", "LBVH with leaves collapsed bottom-up where SAH prefers a leaf", &build_lbvh_sah},
        {"ploc", "parallel locally-ordered clustering (Meister and Bittner 2018), radius 16; one triangle per leaf",
         static_cast<BuildFunction>(&build_ploc)},
        {"sbvh", "split BVH (Stich et al. 2009): binned object and spatial splits, reference unsplitting, 2x reference cap", &build_sbvh},
        {"presplit", "budgeted pre-splitting (Karras and Aila 2013), 50% budget, then binned SAH", &build_presplit},
        {"esc", "early split clipping (Ernst and Greiner 2007) with automatic SA_max, then binned SAH", &build_esc},
        {"sweep", "full sweep SAH (MacDonald and Booth 1990), leaves by SAH termination", &build_sweep_sah},
        {"bittner", "optimiser: removal and reinsertion of inefficient nodes (Bittner et al. 2013)", &build_bittner, "lbvh"},
        {"hillclimb", "optimiser: tree rotations by hill climbing (Kensler 2008)", &build_hillclimb, "lbvh"},
        {"anneal", "optimiser: tree rotations by simulated annealing (Kensler 2008)", &build_anneal, "lbvh"},
        {"treelet", "optimiser: optimal treelet restructuring, 3 rounds (Karras and Aila 2013)", &build_treelet, "lbvh"},
        {"streelet", "Karras and Aila 2013 with splitting: 30% pre-split quota, LBVH, 3 rounds of treelets", &build_streelet},
        {"bonsai", "Bonsai (Ganestam et al. 2015): mid-point partitions, sweep SAH mini-trees, pruning, sweep SAH top tree",
         &build_bonsai},
        {"bonsai-split", "BONSAIS (Ganestam and Doggett 2016): Bonsai with SAH-guided split partitioning", &build_bonsai_split},
        {"sweep-presplit", "SWEEPPRE (Ganestam and Doggett 2016): split partitioning as a pre-split pass, then sweep SAH",
         &build_sweep_presplit},
    };
    return registry;
}

const std::vector<FamilyEntry>& other_families() {
    static const std::vector<FamilyEntry> registry = {
        {kKdTreeName, "SAH kd-tree (Wald and Havran 2006): O(N log N) event sweep, perfect splits, empty-space bonus; "
                      "flat top level only", "kd-tree"},
    };
    return registry;
}

std::vector<BuilderName> all_builders() {
    std::vector<BuilderName> names;
    for (const BuilderEntry& entry : builders()) names.push_back({entry.name, entry.description});
    for (const FamilyEntry& entry : other_families()) names.push_back({entry.name, entry.description});
    return names;
}

bool is_bvh_builder(const std::string& name) {
    return std::any_of(builders().begin(), builders().end(), [&](const BuilderEntry& b) { return b.name == name; });
}

namespace {

[[noreturn]] void unknown_builder(const std::string& name) {
    std::string known;
    for (const BuilderName& entry : all_builders()) known += (known.empty() ? "" : ", ") + entry.name;
    throw std::invalid_argument("unknown builder '" + name + "' (known: " + known + ")");
}

}  // namespace

const BuilderEntry& find_builder(const std::string& name) {
    for (const BuilderEntry& entry : builders())
        if (entry.name == name) return entry;
    for (const FamilyEntry& family : other_families())
        if (family.name == name)
            throw std::invalid_argument("builder '" + name + "' builds a " + family.structure +
                                        ", not a BVH: it has no object BVHs, start trees or BVH kernels");
    unknown_builder(name);
}

void check_builder_name(const std::string& name) {
    const std::vector<BuilderName> names = all_builders();
    if (std::none_of(names.begin(), names.end(), [&](const BuilderName& b) { return b.name == name; })) unknown_builder(name);
}

Bvh build_start_tree(BuildInput&& input, const BuildSettings& settings, const char* default_start) {
    BuildSettings start_settings = settings;
    start_settings.start.clear();
    Bvh start = find_builder(settings.start.empty() ? default_start : settings.start).build(std::move(input), start_settings);
    start.one_ref_leaves.clear();  // the optimiser rewrites the tree
    return start;
}

}  // namespace canopy
