#pragma once
// The builder interface and the registry that chooses builders by name at run time.
// Adding a builder: one file with its build function, one line in registry.cpp.
#include "accel/bvh.h"

#include <list>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace canopy {

struct BuildPlan;  // accel/memory_budget.h

struct BuildInput {
    std::span<const Triangle> triangles;  // split builders clip these; others only read refs
    std::vector<PrimRef> refs;            // one per triangle on entry; the builder may reorder or grow it
};

// A builder's parameters as given in its spec ("sbvh:alpha=1e-5"): key and value text, in the order given. The
// builder parses the values it reads (each entry's BuilderParam checks them first); a key not given is its default.
class BuilderParams {
public:
    const std::string* find(const std::string& key) const;
    void set(const std::string& key, std::string value);
    const std::vector<std::pair<std::string, std::string>>& items() const { return items_; }
    bool empty() const { return items_.empty(); }
    bool operator==(const BuilderParams&) const = default;

private:
    std::vector<std::pair<std::string, std::string>> items_;
};

struct BuildSettings {
    SahCosts costs;
    uint32_t max_leaf_size = 8;  // a leaf is split above this even when SAH prefers a leaf
    uint32_t bins = 32;          // binned builders
    // Triangles the kernel tests at once (1 scalar, 4 SIMD; a power of two): the SAH charges a leaf of n triangles
    // for ceil(n / leaf_block) tests, so SIMD kernels get leaves that fill their lanes.
    uint32_t leaf_block = 1;
    // Optimisers restructure a tree built by another builder: this one, or the optimiser's default if empty.
    std::string start;
    BuilderParams params;  // the builder's own, checked against its entry's list

    float leaf_tests(uint32_t n) const { return float((n + leaf_block - 1) / leaf_block); }
};

using BuildFunction = Bvh (*)(BuildInput&&, const BuildSettings&);

// One parameter a builder takes: `--builder NAME:key=value`.
struct BuilderParam {
    std::string key;
    std::string default_value;
    std::string help;  // one line, for --help and canopy.builders()
    // Throws std::invalid_argument saying what `value` must be; returns it in one spelling per meaning, by which a
    // value is recognised as the default.
    std::string (*canonical)(const std::string& value);
};

// `--builder auto`'s prior of a candidate (renderer/auto_builder.cpp): its build time per triangle built and its
// frame time relative to binned SAH's, by the scene's class as auto_builder.cpp's statistics tell them apart.
struct AutoPrior {
    double build_ns_per_triangle;         // on scenes without slivers
    double sliver_build_ns_per_triangle;  // where splitting builders split (gen:cylinders, gen:foliage)
    double crossing_slivers, clustered_slivers, dense_boxes, architecture, other;  // relative frames
    double instanced = 0.0;  // relative frame on scenes with instances when it differs from the class's; 0 if not
    double max_box_fill = 2.0;  // a candidate only on scenes whose box fill is below this (fills are at most 1)
};

struct BuilderEntry {
    std::string name;
    std::string description;  // one line, for --help and canopy.builders()
    BuildFunction build;
    const char* default_start = nullptr;  // set for optimisers: the builder of their start tree
    std::vector<BuilderParam> params;
    // PrimRef slots the builder allocates per triangle at most: above 1 for builders that split triangles, so the
    // memory bound (accel/memory_budget.h) plans for their growth.
    double reference_cap = 1.0;
    std::optional<AutoPrior> auto_prior;  // set for `--builder auto`'s candidates

    bool optimiser() const { return default_start != nullptr; }
};

// The registered builders: the ones of registry.cpp, then those registered since, in their order. References stay
// valid until their entry is unregistered.
const std::list<BuilderEntry>& builders();

// A builder registered from outside registry.cpp (a test's toy builder); it leaves the registry when this ends.
class BuilderRegistration {
public:
    explicit BuilderRegistration(std::string name) : name_(std::move(name)) {}
    BuilderRegistration(const BuilderRegistration&) = delete;
    BuilderRegistration& operator=(const BuilderRegistration&) = delete;
    ~BuilderRegistration();

private:
    std::string name_;
};
// Throws std::invalid_argument when the name is taken or has a ':' or ','. Not thread-safe against builds.
[[nodiscard]] BuilderRegistration register_builder(BuilderEntry entry);

// A `--builder` value: a name, then optionally ':' and comma-separated key=value pairs
// ("sbvh:alpha=1e-5").
struct BuilderSpec {
    std::string name;
    BuilderParams params;
    // The spec's text without the parameters given at their defaults ("sbvh" for "sbvh:alpha=0.001").
    std::string text() const;
};
// Throws std::invalid_argument naming the builder and the unknown key with the known ones, or the builder's
// check's message for a bad value; unknown names as check_builder_name does.
BuilderSpec parse_builder_spec(const std::string& text);
std::string spec_name(const std::string& spec);  // the name before any ':', unchecked
// A comma-split list of specs put back together: a "key=value" piece without a ':' belongs to the spec before it
// (`--builder sbvh:alpha=1e-5,binned` splits into "sbvh:alpha=1e-5" and "binned").
std::vector<std::string> join_builder_specs(const std::vector<std::string>& pieces);
// PrimRef slots a builder or other family allocates per triangle at most (BuilderEntry::reference_cap); 1 for a
// name registered nowhere ("auto", "embree").
double reference_cap_per_triangle(const std::string& name);
// The memory estimate's plan for a `--builder` spec: its reference cap, and for "auto" the candidates it builds.
BuildPlan make_build_plan(const std::string& spec, int width, bool two_level);
// "key=value (default ...): help" lines of a builder's parameters, for help texts.
std::string builder_params_help(const BuilderEntry& entry);
// Throws InputError-like std::invalid_argument listing the known names when `name` is unknown, or saying what
// `name` builds when it names another structure family.
const BuilderEntry& find_builder(const std::string& name);

// Acceleration structures other than the BVH (the kd-tree), each built and traced by an accelerator of its own
// (make_canopy_accelerator routes their names there). A third family is a line here and a line there.
struct FamilyEntry {
    std::string name, description;
    std::string structure;  // what it builds, for errors: "kd-tree"
    double reference_cap = 1.0;  // as BuilderEntry's
};
const std::vector<FamilyEntry>& other_families();

// Every name `--builder` takes, with its description: builders(), then other_families().
struct BuilderName {
    std::string name, description;
};
std::vector<BuilderName> all_builders();
bool is_bvh_builder(const std::string& name);
// Throws std::invalid_argument listing every name when `spec`'s name is neither a BVH builder nor another family,
// or as parse_builder_spec for its parameters.
void check_builder_name(const std::string& spec);

// The start tree of an optimiser: built by settings.start (a spec), or by `default_start` when that is empty. The
// start builder sees the same settings with its own parameters and no start, so optimisers chain but never recurse.
Bvh build_start_tree(BuildInput&& input, const BuildSettings& settings, const char* default_start);

// One PrimRef per triangle, in parallel. Degenerate triangles keep their (flat) boxes;
// triangles with non-finite vertices are rejected by the scene loaders before this point.
std::vector<PrimRef> make_prim_refs(std::span<const Triangle> triangles);

}  // namespace canopy
