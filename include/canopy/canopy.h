#pragma once
// canopy as a library: build a BVH over triangle meshes with any of canopy's builders, then cast rays one at a
// time or in batches. Only the standard library appears here; the builders, kernels and TBB stay inside
// libcanopy. Every error is a std::invalid_argument whose message starts with the argument it is about, e.g.
// "triangles[7]: vertex index 12 is out of range (10 vertices)".
#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#define CANOPY_API __attribute__((visibility("default")))

namespace canopy {

inline constexpr uint32_t kNoHit = 0xffffffffu;  // the triangle and instance of a miss
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

// One mesh, as views of the caller's arrays, read during the build only.
struct MeshArrays {
    std::span<const float> vertices;      // x, y, z a vertex
    std::span<const uint32_t> triangles;  // three vertex indices a triangle, counter-clockwise or not
};

// A placement of a mesh in the world: world point = transform x (object point, 1), a row-major 3x4 matrix
// (the translation is elements 3, 7 and 11).
struct MeshInstance {
    uint32_t mesh = 0;
    std::array<float, 12> transform{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
};

struct AccelOptions {
    // A name of registered_builders() (binned: the plain SAH build), or "auto": candidates built and timed on a
    // sample of 16 planned frames of the protocol's path tracer (1024 x 768, 8 bounces, the scene's default camera),
    // the least time to image kept.
    std::string builder = "binned";
    std::string kernel = "auto";   // "bvh2", "bvh4", "bvh8", or "auto": the widest this build and CPU run
    bool robust = true;            // traversal that never misses a box the ray touches; false: the fast mode
    bool watertight = true;        // no ray slips between triangles sharing an edge; false: Möller–Trumbore
    // How instances are built: "flat" (one BVH over world triangles), "two-level" (a BVH per mesh under a top
    // level over instances) or "rebraid" (that top level opening mesh BVHs where they overlap). Builder "auto"
    // chooses the top level itself and takes only "flat" here.
    std::string toplevel = "flat";
    int threads = 0;  // for the build and batch queries; 0: all
    // bvh8 nodes: "standard" (256 bytes), or "compressed" (child boxes in bytes, 128 bytes a node, the same hits;
    // slower to trace, for less memory: docs/results.md#compressed-bvh8-nodes): a named builder, kernel bvh8 and a
    // flat top level only.
    std::string layout = "standard";
    // How bvh4 and bvh8 are made: "" for the builder's own ("direct" for lbvh's flat trees, its wide tree straight
    // from the Morton codes, the fastest build; "optimal" for every other), or "optimal" (the least-cost collapse of
    // the binary tree), "greedy", "direct" (builder lbvh, kernel bvh4 or bvh8, top level flat).
    std::string collapse;
};

struct RayHit {
    float t = kInfinity;      // distance along the direction (in units of its length); infinity for a miss
    float u = 0.0f, v = 0.0f;  // barycentric weights of the triangle's second and third vertex
    uint32_t triangle = kNoHit;  // index into its mesh's triangles
    uint32_t instance = kNoHit;  // index of the instance hit; without instances, the mesh's index

    bool found() const { return triangle != kNoHit; }
};

// A batch of rays as views of the caller's arrays. tmin and tmax hold one value a ray, or one for every ray, or
// nothing (0 and infinity); a ray finds hits in (tmin, tmax], tmin >= 0. t is a hit's distance to double precision
// on its triangle, rounded to float, so short hits keep their relative precision; a surface through the origin
// (t = 0) is never hit.
struct RayBatch {
    std::span<const float> origins;     // x, y, z a ray
    std::span<const float> directions;  // x, y, z a ray; need not be unit length
    std::span<const float> tmin;
    std::span<const float> tmax;
    // A ray with a non-finite origin or direction or a NaN tmin or tmax: false, the query throws naming it; true,
    // it answers as a miss (what batch pipelines expect of one bad row). A negative tmin always throws.
    bool invalid_rays_miss = false;
};

// Where a batch's closest hits go: each view holds one value a ray, or is empty when not wanted. Misses get t
// infinity, triangle and instance kNoHit, u and v 0.
struct HitBatch {
    std::span<float> t;
    std::span<uint32_t> triangle;
    std::span<float> u, v;
    std::span<uint32_t> instance;
    std::span<float> normal;  // x, y, z a ray: the hit triangle's unit geometric normal (v1 - v0) x (v2 - v0) in the
                              // world, zeros for a miss
};

// Every hit along each ray of a batch: ray i's hits are entries [offsets[i], offsets[i + 1]), ordered by t (then by
// instance and triangle), each triangle once.
struct HitList {
    std::vector<uint64_t> offsets;  // one more than the rays
    std::vector<float> t, u, v;
    std::vector<uint32_t> triangle, instance;
};

// Where a batch of closest-point queries goes: each view holds one value a point (point: three), or is empty when
// not wanted. A point that finds nothing (no triangles, or a non-finite point answered as a miss) gets distance
// infinity, point NaN, triangle and instance kNoHit.
struct PointBatch {
    std::span<float> point;  // x, y, z a query: the nearest point on the surface
    std::span<float> distance;
    std::span<uint32_t> triangle, instance;
    std::span<float> u, v;  // barycentric weights of the triangle's second and third vertex at that point
};

struct AccelStats {
    // The builder that built (for "auto", the one it chose): a two-level top level before it, an optimiser's
    // start tree after it, e.g. "sbvh", "rebraid/binned", "bittner<lbvh".
    std::string builder;
    std::string kernel;    // width and modes, e.g. "bvh8" or "bvh4 fast mt"
    std::string reason;    // "auto": the statistics and predicted times that decided; otherwise empty
    uint64_t triangles = 0;  // in the world, every instance's copy counted
    double build_ms = 0;     // the build, from the triangles in world or object space to the traced layout
    // Of the builder's binary tree (flat builds): surface area heuristic cost (eq. 1 of Aila, Karras and Laine
    // 2013) and end-point overlap (their eq. 3, computed only when asked for: exact clipping takes seconds).
    std::optional<double> sah, epo;
    std::optional<double> layout_sah;  // the same SAH of the traced layout (wide nodes; two-level: as traversed)
    std::optional<uint64_t> nodes, leaves, depth;  // two-level: the top level's nodes and leaf references
    std::optional<double> references_per_triangle;  // above 1 where a builder split triangles
    uint64_t bytes = 0;                              // the traced layout: nodes and leaf triangles
};

struct BuilderParamDescription {
    std::string key;            // AccelOptions::builder takes "NAME:key=value,key=value"
    std::string default_value;
    std::string help;
};

struct BuilderDescription {
    std::string name;
    std::string description;
    std::vector<BuilderParamDescription> params;
};

// An accelerator over meshes, built once, then queried from any number of threads at once.
class CANOPY_API Accel {
public:
    explicit Accel(const MeshArrays& mesh, const AccelOptions& options = {});
    // Without instances every mesh is placed once, untransformed, as instance number = its index.
    Accel(std::span<const MeshArrays> meshes, std::span<const MeshInstance> instances, const AccelOptions& options = {});
    ~Accel();
    Accel(Accel&&) noexcept;
    Accel& operator=(Accel&&) noexcept;

    // One ray on the calling thread. origin and direction must be finite, tmin and tmax not NaN.
    RayHit intersect(const std::array<float, 3>& origin, const std::array<float, 3>& direction, float tmin = 0.0f,
                     float tmax = kInfinity) const;
    bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction, float tmin = 0.0f,
                  float tmax = kInfinity) const;

    // A batch on the accelerator's threads, through canopy's batch kernel (16-ray packets); each ray's answer is
    // the single-ray query's, bit for bit (with robust watertight traversal; the fast modes may differ where two
    // triangles are within rounding of each other). An empty batch does nothing.
    void intersect(const RayBatch& rays, const HitBatch& hits) const;
    void occluded(const RayBatch& rays, std::span<bool> occluded) const;

    // Every hit along each ray, or their number, a triangle hit on a shared edge counted once a triangle. Need a
    // flat tree of standard nodes (toplevel "flat", layout "standard", not builder "kdtree"): std::invalid_argument
    // otherwise, as for the point queries below.
    void intersect_all(const RayBatch& rays, HitList& hits) const;
    void count_hits(const RayBatch& rays, std::span<uint32_t> counts) const;

    // The nearest surface point of each point (x, y, z a query), through the tree: points must be finite, unless
    // invalid_points_miss, when a non-finite point answers as a miss.
    void closest_points(std::span<const float> points, const PointBatch& out, bool invalid_points_miss = false) const;
    // Whether each point lies inside the surface, by the parity of a ray's crossings, the majority of three rays
    // of fixed directions (one alone errs where it grazes an edge). Meant for closed meshes; a non-finite point is
    // outside with invalid_points_miss, otherwise it throws.
    void contains(std::span<const float> points, std::span<bool> inside, bool invalid_points_miss = false) const;

    AccelStats stats(bool with_epo = false) const;

    // Throws what a query of this batch would throw for its arrays and rays (for callers that answer a batch
    // without an accelerator, such as a scene of no triangles).
    static void check_rays(const RayBatch& rays);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

CANOPY_API std::vector<BuilderDescription> registered_builders();

// Triangles in world space, three vertices each: what load_triangles() returns.
struct TriangleMesh {
    std::vector<float> vertices;      // x, y, z a vertex
    std::vector<uint32_t> triangles;  // 0, 1, 2, 3, ...: the vertices in threes
};

// Loads what canopy's command loads (an .obj, .gltf or .glb file, a scene.json, or a generator "gen:NAME?tris=N"),
// every instance placed in world space. Throws std::invalid_argument naming the file and field of bad input.
CANOPY_API TriangleMesh load_triangles(const std::string& path);

}  // namespace canopy
