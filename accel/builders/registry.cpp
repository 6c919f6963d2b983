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
#include "accel/builders/split_partitioning.h"
#include "accel/builders/sbvh.h"
#include "accel/builders/sweep_sah.h"
#include "accel/builders/streelet.h"
#include "accel/builders/tree_rotations.h"
#include "accel/builders/treelet_restructuring.h"
#include "accel/kdtree.h"
#include "accel/memory_budget.h"

#include <algorithm>
#include <stdexcept>

namespace canopy {

namespace {

// A candidate's prior: build time per triangle built (without and with slivers), and frames relative to binned's in
// the order crossing slivers, clustered slivers, dense boxes, other architecture, other scenes (engine/auto_builder.cpp
// tells them apart), each about the middle of what the builder's frames measured in that class. Fitted on bench runs of
// every candidate over the shared scenes and the procedural classes, and builds scaled by each builder's later
// measured speed-ups (docs/results.md#autos-priors-and-samples), so the priors have seen those scenes: they only order
// the calibration and predict the candidates it does not measure.
constexpr AutoPrior kBinnedPrior{145.0, 145.0, 1.0, 1.0, 1.0, 1.0, 1.0};
constexpr AutoPrior kBonsaiSplitPrior{280.0, 450.0, 0.64, 0.53, 0.92, 1.07, 1.01};
// The same tree as binned where its automatic SA_max does not split, so no candidate there.
constexpr AutoPrior kEscPrior{160.0, 710.0, 0.41, 0.51, 1.0, 1.0, 1.0, 0.0, kEscMaxFillToSplit};
// sbvh's build is binned's times the geometric mean of their ratio; where binned's tree is measured, auto predicts
// sbvh's frame from its overlap instead.
constexpr AutoPrior kSbvhPrior{570.0, 1750.0, 0.73, 0.47, 0.87, 1.0, 1.0};
// Full sweeps instead of bins: within a few percent of binned's frames everywhere.
constexpr AutoPrior kSweepPrior{330.0, 330.0, 1.0, 1.0, 1.0, 1.0, 1.0};
constexpr AutoPrior kBittnerPrior{3300.0, 11000.0, 0.78, 0.88, 0.85, 0.96, 1.04};
// lbvh's default, the direct wide tree from the Morton codes, a fraction of the optimal collapse's build; instances
// (whose flattened Morton order interleaves the instances' triangles) the optimal collapse's prior times the rooms'
// ratio to it. The cheapest build, so it wins where a frame is cheap against building.
constexpr AutoPrior kLbvhPrior{45.0, 45.0, 1.6, 1.6, 1.4, 1.4, 1.12, 1.38};

std::list<BuilderEntry> canopy_builders() {
    return {
        {"agglo", "agglomerative clustering (Walter et al. 2008): closest pair by merged box area; one triangle per leaf",
         &build_agglomerative},
        {"binned", "parallel binned SAH (Wald 2007), leaves by SAH termination", &build_binned_sah, nullptr, {}, 1.0, kBinnedPrior},
        {"lbvh", "linear BVH: Morton codes, radix sort, Karras 2012 hierarchy; one triangle per leaf", &build_lbvh, nullptr, {},
         1.0, kLbvhPrior},
        {"lbvh-sah", "LBVH with leaves collapsed bottom-up where SAH prefers a leaf", &build_lbvh_sah},
        {"ploc", "parallel locally-ordered clustering (Meister and Bittner 2018), radius 16; one triangle per leaf",
         static_cast<BuildFunction>(&build_ploc)},
        {"sbvh", "split BVH (Stich et al. 2009): binned object and spatial splits, reference unsplitting, 2x reference cap",
         &build_sbvh, nullptr, sbvh_params(), SbvhSettings{}.max_references_per_triangle, kSbvhPrior},
        {"presplit", "budgeted pre-splitting (Karras and Aila 2013), 50% budget, then binned SAH", &build_presplit, nullptr, {},
         1.0 + PresplitSettings{}.budget},
        {"esc", "early split clipping (Ernst and Greiner 2007), then binned SAH", &build_esc, nullptr, esc_params(),
         kMaxEscReferencesPerTriangle, kEscPrior},
        {"sweep", "full sweep SAH (MacDonald and Booth 1990), leaves by SAH termination", &build_sweep_sah, nullptr, {}, 1.0,
         kSweepPrior},
        {"bittner", "optimiser: removal and reinsertion of inefficient nodes (Bittner et al. 2013)", &build_bittner, "lbvh", {},
         1.0, kBittnerPrior},
        {"hillclimb", "optimiser: tree rotations by hill climbing (Kensler 2008)", &build_hillclimb, "lbvh"},
        {"anneal", "optimiser: tree rotations by simulated annealing (Kensler 2008)", &build_anneal, "lbvh"},
        {"treelet", "optimiser: optimal treelet restructuring, 3 rounds (Karras and Aila 2013)", &build_treelet, "lbvh"},
        {"streelet", "Karras and Aila 2013 with splitting: 30% pre-split quota, LBVH, 3 rounds of treelets", &build_streelet,
         nullptr, {}, 1.3},
        {"bonsai", "Bonsai (Ganestam et al. 2015): mid-point partitions, sweep SAH mini-trees, pruning, sweep SAH top tree",
         &build_bonsai},
        {"bonsai-split", "BONSAIS (Ganestam and Doggett 2016): Bonsai with SAH-guided split partitioning", &build_bonsai_split,
         nullptr, {}, kMaxReferenceCapacity, kBonsaiSplitPrior},
        {"sweep-presplit", "SWEEPPRE (Ganestam and Doggett 2016): split partitioning as a pre-split pass, then sweep SAH",
         &build_sweep_presplit, nullptr, {}, kMaxReferenceCapacity},
    };
}

std::list<BuilderEntry>& registry() {
    static std::list<BuilderEntry> entries = canopy_builders();
    return entries;
}

}  // namespace

const std::list<BuilderEntry>& builders() { return registry(); }

BuilderRegistration register_builder(BuilderEntry entry) {
    if (entry.name.empty() || entry.name.find_first_of(":,") != std::string::npos)
        throw std::invalid_argument("builder name '" + entry.name + "': not empty, without ':' or ','");
    const std::vector<BuilderName> names = all_builders();
    if (entry.name == "auto" || std::any_of(names.begin(), names.end(), [&](const BuilderName& b) { return b.name == entry.name; }))
        throw std::invalid_argument("builder '" + entry.name + "' is registered already");
    std::string name = entry.name;
    registry().push_back(std::move(entry));
    return BuilderRegistration(std::move(name));
}

BuilderRegistration::~BuilderRegistration() {
    registry().remove_if([&](const BuilderEntry& entry) { return entry.name == name_; });
}

const std::vector<FamilyEntry>& other_families() {
    static const std::vector<FamilyEntry> registry = {
        {kKdTreeName, "SAH kd-tree (Wald and Havran 2006): O(N log N) event sweep, perfect splits, empty-space bonus; "
                      "flat top level only", "kd-tree", KdSettings{}.max_references_per_triangle},
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

namespace {

// The parameters a name takes: a BVH builder's list, none for another family; unknown names throw.
const std::vector<BuilderParam>& params_of(const std::string& name) {
    static const std::vector<BuilderParam> none;
    for (const BuilderEntry& entry : builders())
        if (entry.name == name) return entry.params;
    for (const FamilyEntry& family : other_families())
        if (family.name == name) return none;
    unknown_builder(name);
}

std::string known_keys(const std::vector<BuilderParam>& params) {
    if (params.empty()) return "it takes none";
    std::string keys;
    for (const BuilderParam& p : params) keys += (keys.empty() ? "" : ", ") + p.key;
    return "known: " + keys;
}

const BuilderParam& find_param(const std::string& builder, const std::vector<BuilderParam>& params, const std::string& key) {
    for (const BuilderParam& p : params)
        if (p.key == key) return p;
    throw std::invalid_argument("builder '" + builder + "' has no parameter '" + key + "' (" + known_keys(params) + ")");
}

}  // namespace

const std::string* BuilderParams::find(const std::string& key) const {
    for (const auto& [k, value] : items_)
        if (k == key) return &value;
    return nullptr;
}

void BuilderParams::set(const std::string& key, std::string value) {
    for (auto& [k, v] : items_)
        if (k == key) {
            v = std::move(value);
            return;
        }
    items_.emplace_back(key, std::move(value));
}

std::string BuilderSpec::text() const {
    const std::vector<BuilderParam>& known = params_of(name);
    std::string pairs;
    for (const auto& [key, value] : params.items()) {
        const BuilderParam& p = find_param(name, known, key);
        if (p.canonical(value) == p.canonical(p.default_value)) continue;
        pairs += (pairs.empty() ? "" : ",") + key + "=" + value;
    }
    return pairs.empty() ? name : name + ":" + pairs;
}

std::string spec_name(const std::string& spec) { return spec.substr(0, spec.find(':')); }

BuilderSpec parse_builder_spec(const std::string& text) {
    BuilderSpec spec{spec_name(text), {}};
    const std::vector<BuilderParam>& known = params_of(spec.name);
    if (spec.name.size() == text.size()) return spec;
    const std::string pairs = text.substr(spec.name.size() + 1);
    for (size_t begin = 0; begin <= pairs.size();) {
        const size_t end = std::min(pairs.find(',', begin), pairs.size());
        const std::string pair = pairs.substr(begin, end - begin);
        const size_t equals = pair.find('=');
        if (equals == std::string::npos || equals == 0)
            throw std::invalid_argument("builder '" + spec.name + "': '" + pair + "' is no key=value (" + known_keys(known) + ")");
        const std::string key = pair.substr(0, equals), value = pair.substr(equals + 1);
        const BuilderParam& param = find_param(spec.name, known, key);
        if (spec.params.find(key)) throw std::invalid_argument("builder '" + spec.name + "': parameter '" + key + "' given twice");
        param.canonical(value);  // throws for a bad value, naming it
        spec.params.set(key, value);
        begin = end + 1;
    }
    return spec;
}

std::vector<std::string> join_builder_specs(const std::vector<std::string>& pieces) {
    std::vector<std::string> specs;
    for (const std::string& piece : pieces) {
        const size_t equals = piece.find('='), colon = piece.find(':');
        const bool continues = equals != std::string::npos && (colon == std::string::npos || colon > equals);
        if (continues && !specs.empty() && specs.back().find(':') != std::string::npos) specs.back() += "," + piece;
        else specs.push_back(piece);
    }
    return specs;
}

std::string builder_params_help(const BuilderEntry& entry) {
    std::string help;
    for (const BuilderParam& p : entry.params)
        help += "\n    " + entry.name + ":" + p.key + "=... (default " + p.default_value + "): " + p.help;
    return help;
}

double reference_cap_per_triangle(const std::string& builder) {
    for (const BuilderEntry& entry : builders())
        if (entry.name == builder) return entry.reference_cap;
    for (const FamilyEntry& family : other_families())
        if (family.name == builder) return family.reference_cap;
    return 1.0;
}

BuildPlan make_build_plan(const std::string& spec, int width, bool two_level) {
    BuildPlan plan{spec, width, two_level, reference_cap_per_triangle(spec_name(spec)), {}};
    if (spec != "auto") return plan;
    for (const BuilderEntry& candidate : builders())
        if (candidate.auto_prior) plan.auto_candidates.push_back({candidate.name, width, false, candidate.reference_cap, {}});
    return plan;
}

void check_builder_name(const std::string& spec) { parse_builder_spec(spec); }

Bvh build_start_tree(BuildInput&& input, const BuildSettings& settings, const char* default_start) {
    const BuilderSpec spec = parse_builder_spec(settings.start.empty() ? default_start : settings.start);
    BuildSettings start_settings = settings;
    start_settings.start.clear();
    start_settings.params = spec.params;
    Bvh start = find_builder(spec.name).build(std::move(input), start_settings);
    start.one_ref_leaves.clear();  // the optimiser rewrites the tree
    return start;
}

}  // namespace canopy
