#include "accel/memory_budget.h"

#include "accel/bvh.h"
#include "accel/kdtree.h"
#include "accel/wide_bvh.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <utility>

namespace canopy {
namespace {

// Vectors grown one element at a time (loaders, generators) hold up to twice their size, and a reallocation
// briefly holds the old array beside the new one.
constexpr uint64_t kGrowthSlack = 2;
constexpr uint64_t kVertexBytes = sizeof(Vec3);
constexpr uint64_t kMeshTriangleBytes = sizeof(glm::uvec3) + sizeof(uint32_t);  // indices and material
constexpr uint64_t kFlatTriangleBytes = sizeof(Triangle) + sizeof(uint32_t);    // world triangle and material
// A PrimRef array and the builders' second array of the same size (partition buffers, sorted copies, clustering).
constexpr uint64_t kReferenceBytes = 2 * sizeof(PrimRef);
// At most 2n - 1 nodes for n leaf references, and the references themselves.
constexpr uint64_t kBinaryBytesPerReference = 2 * sizeof(BvhNode) + sizeof(uint32_t);
// A wide node per N / 2 references at most (every inner node of the binary tree is a wide node only when the
// collapse opens nothing, then every wide node holds at least 2 children); leaves: a LeafTriangle each for
// bvh2, and for the SIMD widths up to half the lanes of a triangle block left empty.
constexpr uint64_t wide_node_bytes_per_reference(int width) {
    switch (width) {
        case 2: return sizeof(WideNode<2>);
        case 4: return sizeof(WideNode<4>) / 2;
        default: return sizeof(WideNode<8>) / 4;
    }
}
constexpr uint64_t leaf_bytes_per_reference(int width) {
    if (width == 2) return sizeof(LeafTriangle);
    return 2 * sizeof(LeafOf<8>) / uint64_t(block_lanes(8));
}
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

MemoryEstimate build_terms(const SceneSize& size, const BuildPlan& plan) {
    MemoryEstimate e;
    const uint64_t triangles = plan.two_level ? size.triangles : size.instanced_triangles;
    const auto references = uint64_t(double(triangles) * reference_cap_per_triangle(spec_name(plan.builder))) + 1;
    if (spec_name(plan.builder) == kKdTreeName) {  // no PrimRefs, binary BVH or wide layout
        e.references = references * kKdBuildBytesPerReference;
        e.layout = references * kKdTreeBytesPerReference;
        return e;
    }
    e.references = references * kReferenceBytes;
    e.binary = references * kBinaryBytesPerReference;
    e.layout = references * (wide_node_bytes_per_reference(plan.width) + leaf_bytes_per_reference(plan.width));
    if (plan.two_level) {
        e.flat = size.triangles * sizeof(Triangle);  // object-space copies of every object's triangles
        e.layout += size.instances * kPlacementBytes;
    }
    return e;
}

MemoryEstimate plan_terms(const SceneSize& size, const BuildPlan& plan) {
    if (plan.builder != "auto") return build_terms(size, plan);
    MemoryEstimate largest = build_terms(size, {"binned", plan.width, true});
    uint64_t kept = largest.layout;
    // auto's candidates (the builders with a prior): the largest of theirs, plus the largest layout again, as its
    // calibration keeps the best tree so far while it builds the next.
    for (const BuilderEntry& candidate : builders()) {
        if (!candidate.auto_prior) continue;
        const MemoryEstimate e = build_terms(size, {candidate.name, plan.width, false});
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

uint64_t resident_bytes() {
    std::ifstream in("/proc/self/statm");
    uint64_t size = 0, resident = 0;
    in >> size >> resident;
    return resident * 4096;
}

struct CgroupFiles {
    const char* limit;
    const char* usage;
};

}  // namespace

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
    const std::pair<const char*, uint64_t> terms[] = {{"scene", scene}, {"flat triangles", flat},
                                                      {"references and build scratch", references},
                                                      {"binary BVH", binary}, {"traversal layout", layout}};
    std::string parts;
    for (const auto& [name, bytes] : terms)
        if (bytes) parts += (parts.empty() ? "" : ", ") + std::string(name) + " " + format_bytes(bytes);
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

void require_memory(const std::string& what, const MemoryEstimate& estimate, const MemoryAvailable& available) {
    if (estimate.total() <= available.bytes) return;
    throw MemoryError(what + ": not enough memory: building it needs about " + estimate.describe() + ", but " +
                      format_bytes(available.bytes) + " is available (" + available.source +
                      "); try a smaller scene or a builder that does not split");
}

}  // namespace canopy
