#include "accel/memory_budget.h"

#include "accel/builder.h"  // BuildSettings's leaf size: the header alone, not the registry
#include "accel/bvh.h"
#include "accel/kdtree.h"
#include "accel/wide_bvh.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <string_view>
#include <utility>

namespace canopy {
namespace {

// Vectors grown one element at a time (loaders, generators) hold up to twice their size, and a reallocation
// briefly holds the old array beside the new one.
constexpr uint64_t kGrowthSlack = 2;
constexpr uint64_t kVertexBytes = sizeof(Vec3);
constexpr uint64_t kMeshTriangleBytes = sizeof(glm::uvec3) + sizeof(uint32_t);  // indices and material
constexpr uint64_t kFlatTriangleBytes = sizeof(Triangle) + sizeof(uint32_t);    // world triangle and material
// A PrimRef array and the builders' second array of the same size (partition buffers, sorted copies, clustering,
// or the parallel builders' node slots and their compacted copy).
constexpr uint64_t kReferenceBytes = 2 * sizeof(PrimRef);
// The SAH charges a leaf by the blocks of lanes it fills (BuildSettings::leaf_block), so with block leaves a leaf
// below the size cap costs no more than a one-triangle leaf and leaves fill up: three quarters of the cap on average
// (docs/results.md, "Memory estimate"). Binary leaves for the scalar kernel are charged per triangle and stay small.
constexpr double kBlockLeafFill = 0.75;
constexpr double kScalarLeafTriangles = 2.0;
double references_per_leaf(int width) {
    return width > 2 ? kBlockLeafFill * double(BuildSettings{}.max_leaf_size) : kScalarLeafTriangles;
}
// 2 l - 1 nodes for l leaves, and the references themselves.
double binary_bytes_per_reference(int width) {
    return 2.0 * double(sizeof(BvhNode)) / references_per_leaf(width) + double(sizeof(uint32_t));
}
// Leaves: a triangle block per leaf (a leaf never exceeds the cap, which is one block), a LeafTriangle per reference
// for bvh2. Wide nodes: the collapse opens binary nodes until a wide node has N children, at least N / 2 of them
// leaves on average (the leaves sit in the tree's last levels), so a wide node per N / 2 leaves at most.
double layout_bytes_per_reference(int width) {
    const double leaves_per_reference = 1.0 / references_per_leaf(width);
    const auto node_bytes = [&](double node_size) { return node_size * leaves_per_reference / (width / 2.0); };
    switch (width) {
        case 2: return double(sizeof(LeafTriangle)) + node_bytes(sizeof(WideNode<2>));
        case 4: return double(sizeof(LeafOf<4>)) * leaves_per_reference + node_bytes(sizeof(WideNode<4>));
        default: return double(sizeof(LeafOf<8>)) * leaves_per_reference + node_bytes(sizeof(WideNode<8>));
    }
}
// Embree's row (renderer/embree_accel.cpp) copies the flat triangles into its own vertex and index buffers, and
// Embree's MEDIUM build holds a PrimRef array beside its growing BVH8 of four-triangle leaves: the tree's bytes per
// triangle are what peak resident memory showed over the copy and the PrimRefs (/usr/bin/time -v on the bench with
// and without its Embree row; docs/results.md, "Memory estimate").
constexpr uint64_t kEmbreeCopyBytes = sizeof(Triangle) + 3 * sizeof(uint32_t);
constexpr uint64_t kEmbreeTreeBytes = 72;
constexpr uint64_t kEmbreeBuildBytes = sizeof(PrimRef);
// The kd-tree's build (accel/kdtree.cpp) per reference: six 12-byte events in a node's list, in the copy kept
// for a child and in the child's merged list; the clipped box and triangle index in the node and in a child; the
// index maps and side flag of the partition.
constexpr uint64_t kKdBuildBytesPerReference = 3 * 6 * 12 + 2 * (sizeof(BBox) + sizeof(uint32_t)) + 2 * sizeof(uint32_t) + 1;
// The kd-tree itself per reference: a leaf block (a leaf of c references takes ceil(c / lanes) <= c blocks: a whole
// one per reference when every leaf holds one), the build's reference, and nodes: a leaf per reference at most, with
// the inner node above it, and as many again for the empty leaves the empty-space bonus cuts off.
constexpr uint64_t kKdTreeBytesPerReference = sizeof(KdBlock) + sizeof(uint32_t) + 4 * sizeof(KdNode);
// A two-level placement: its inverse and world transforms, and the top level's BRefs (re-braiding opens a
// placement into a bounded number of them) with their share of top-level nodes.
constexpr uint64_t kPlacementBytes = 1024;

// The builder's name without its parameters ("sbvh" for "sbvh:alpha=1e-5").
std::string_view builder_name(const BuildPlan& plan) {
    return std::string_view(plan.builder).substr(0, plan.builder.find(':'));
}

MemoryEstimate build_terms(const SceneSize& size, const BuildPlan& plan) {
    MemoryEstimate e;
    const uint64_t triangles = plan.two_level ? size.triangles : size.instanced_triangles;
    const auto references = uint64_t(double(triangles) * plan.reference_cap) + 1;
    if (plan.builder == "embree") {
        e.flat = triangles * kEmbreeCopyBytes;
        e.references = triangles * kEmbreeBuildBytes;
        e.layout = triangles * kEmbreeTreeBytes;
        return e;
    }
    if (builder_name(plan) == kKdTreeName) {  // no PrimRefs, binary BVH or wide layout
        e.references = references * kKdBuildBytesPerReference;
        e.layout = references * kKdTreeBytesPerReference;
        return e;
    }
    // PrimRefs and build scratch are freed before the collapse writes the layout: only what exceeds it adds to the peak.
    e.references = references * kReferenceBytes;
    e.binary = uint64_t(double(references) * binary_bytes_per_reference(plan.width));
    e.layout = uint64_t(double(references) * layout_bytes_per_reference(plan.width));
    if (plan.two_level) {
        e.flat = size.triangles * sizeof(Triangle);  // object-space copies of every object's triangles
        e.layout += size.instances * kPlacementBytes;
    }
    e.references = e.references > e.layout ? e.references - e.layout : 0;
    return e;
}

MemoryEstimate plan_terms(const SceneSize& size, const BuildPlan& plan) {
    if (plan.builder != "auto") return build_terms(size, plan);
    MemoryEstimate largest = build_terms(size, {"binned", plan.width, true});
    uint64_t kept = largest.layout;
    // The largest of its candidates' builds, plus the largest layout again, as its calibration keeps the best tree
    // so far while it builds the next.
    for (const BuildPlan& candidate : plan.auto_candidates) {
        const MemoryEstimate e = build_terms(size, candidate);
        if (e.total() > largest.total()) largest = e;
        kept = std::max(kept, e.layout);
    }
    largest.layout += kept;
    return largest;
}

// A "Key:   123 kB" line of /proc/meminfo, in bytes.
std::optional<uint64_t> meminfo_bytes(const std::string& key) {
    std::ifstream in("/proc/meminfo");
    for (std::string line; std::getline(in, line);) {
        if (!line.starts_with(key + ":")) continue;
        uint64_t kib = 0;
        std::istringstream(line.substr(key.size() + 1)) >> kib;
        return kib * 1024;
    }
    return std::nullopt;
}

// One number in a file; nothing for "max", a missing file or anything else.
std::optional<uint64_t> number_in_file(const std::string& path) {
    std::ifstream in(path);
    uint64_t value = 0;
    if (!(in >> value)) return std::nullopt;
    return value;
}

struct CgroupFiles {
    const char* limit;
    const char* usage;
};

}  // namespace

uint64_t resident_bytes() {
    std::ifstream in("/proc/self/statm");
    uint64_t size = 0, resident = 0;
    in >> size >> resident;
    return resident * 4096;
}

MemoryEstimate estimate_memory(const SceneSize& size, std::span<const BuildPlan> plans) {
    MemoryEstimate total;
    total.scene = kGrowthSlack * (size.vertices * kVertexBytes + size.triangles * kMeshTriangleBytes);
    total.flat = size.instanced_triangles * kFlatTriangleBytes;
    for (const BuildPlan& plan : plans) {
        const MemoryEstimate e = plan_terms(size, plan);
        total.flat += e.flat;
        total.references = std::max(total.references, e.references);  // one build at a time
        total.binary += e.binary;
        total.layout += e.layout;
    }
    return total;
}

std::string format_bytes(uint64_t bytes) {
    constexpr const char* units[] = {"KiB", "MiB", "GiB", "TiB"};
    if (bytes < 1024) return std::to_string(bytes) + " bytes";
    double value = double(bytes) / 1024.0;
    int unit = 0;
    for (; value >= 1024.0 && unit < 3; ++unit) value /= 1024.0;
    char text[32];
    std::snprintf(text, sizeof text, "%.1f %s", value, units[unit]);
    return text;
}

// The terms a build has (a kd-tree has no binary BVH): "61.3 GiB (scene 17.9 GiB, flat triangles 14.9 GiB, ...)".
std::string MemoryEstimate::describe() const {
    const std::pair<const char*, uint64_t> terms[] = {{"process", process}, {"scene", scene}, {"flat triangles", flat},
                                                      {"references and build scratch", references},
                                                      {"binary BVH", binary}, {"traversal layout", layout},
                                                      {"images and batches", frames}};
    std::string parts;
    for (const auto& [name, bytes] : terms)  // a term under a KiB (a rounding remainder) says nothing beside MiB
        if (bytes >= 1024) parts += (parts.empty() ? "" : ", ") + std::string(name) + " " + format_bytes(bytes);
    return format_bytes(total()) + " (" + parts + ")";
}

MemoryAvailable available_memory(std::optional<uint64_t> limit) {
    const uint64_t held = resident_bytes();
    MemoryAvailable available{UINT64_MAX, "nothing: /proc/meminfo and the cgroup files are unreadable"};
    if (const auto free = meminfo_bytes("MemAvailable")) available = {*free + held, "MemAvailable in /proc/meminfo"};
    for (const CgroupFiles files : {CgroupFiles{"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"},
                                    CgroupFiles{"/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                                "/sys/fs/cgroup/memory/memory.usage_in_bytes"}}) {
        const auto cap = number_in_file(files.limit), used = number_in_file(files.usage);
        if (!cap || !used) continue;
        const uint64_t left = (*cap > *used ? *cap - *used : 0) + held;
        if (left < available.bytes) available = {left, std::string("the cgroup limit in ") + files.limit};
    }
    if (limit && *limit < available.bytes) available = {*limit, "--memory-limit"};
    return available;
}

// What would shrink the estimate most: the images when they outweigh everything the scene and its tree take.
const char* remedy(const MemoryEstimate& estimate) {
    if (estimate.frames > estimate.total() - estimate.frames) return "try a smaller image (--size)";
    return "try a smaller scene or a builder that does not split";
}

void require_memory(const std::string& what, const MemoryEstimate& estimate, const MemoryAvailable& available) {
    if (estimate.total() <= available.bytes) return;
    throw MemoryError(what + ": not enough memory: building it needs about " + estimate.describe() + ", but " +
                      format_bytes(available.bytes) + " is available (" + available.source + "); " + remedy(estimate));
}

}  // namespace canopy
