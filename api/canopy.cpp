// The public API over the engine: input arrays become a Scene (meshes, instances) and its flattened world
// triangles, from which make_canopy_accelerator() builds as `canopy render` and `canopy bench` do; queries go to
// the accelerator's single-ray kernel or its batch kernel, batches split across the accelerator's threads.
#include "canopy/canopy.h"

#include "accel/builder.h"
#include "kernels/all_hits.h"
#include "kernels/closest_point.h"
#include "kernels/dispatch.h"
#include "kernels/precise_distance.h"
#include "engine/accelerator.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <immintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>

namespace canopy {
namespace {

// Rays a task of a batch converts and traces at once: enough for full packets, few enough for the stack.
constexpr size_t kBatchChunk = 1024;

// Runs f, putting the argument `name` in front of the message of a std::invalid_argument it throws.
template <class F>
auto naming(const std::string& name, F&& f) {
    try {
        return f();
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(name + ": " + e.what());
    }
}

std::string describe(float value) { return std::isnan(value) ? "nan" : value > 0 ? "inf" : "-inf"; }

// Throws naming the first non-finite coordinate of the points `values` (x, y, z each), numbered from `first`.
void check_finite_xyz(std::span<const float> values, const std::string& name, size_t first = 0) {
    for (size_t i = 0; i < values.size(); ++i)
        if (!std::isfinite(values[i]))
            throw std::invalid_argument(name + "[" + std::to_string(first + i / 3) + "]: " + "xyz"[i % 3] + " is " + describe(values[i]));
}

void check_triples(std::span<const float> values, const std::string& name) {
    if (values.size() % 3 != 0)
        throw std::invalid_argument(name + ": " + std::to_string(values.size()) + " values, not a multiple of 3");
}

Mesh to_mesh(const MeshArrays& arrays, const std::string& prefix) {
    const std::string vertices = prefix + "vertices", triangles = prefix + "triangles";
    if (arrays.vertices.empty()) throw std::invalid_argument(vertices + ": empty");
    if (arrays.triangles.empty()) throw std::invalid_argument(triangles + ": empty");
    check_triples(arrays.vertices, vertices);
    if (arrays.triangles.size() % 3 != 0)
        throw std::invalid_argument(triangles + ": " + std::to_string(arrays.triangles.size()) + " indices, not a multiple of 3");
    check_finite_xyz(arrays.vertices, vertices);
    Mesh mesh;
    mesh.positions.resize(arrays.vertices.size() / 3);
    for (size_t i = 0; i < mesh.positions.size(); ++i)
        mesh.positions[i] = {arrays.vertices[3 * i], arrays.vertices[3 * i + 1], arrays.vertices[3 * i + 2]};
    mesh.triangles.resize(arrays.triangles.size() / 3);
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
        const glm::uvec3 f{arrays.triangles[3 * i], arrays.triangles[3 * i + 1], arrays.triangles[3 * i + 2]};
        const uint32_t largest = std::max({f.x, f.y, f.z});
        if (largest >= mesh.positions.size())
            throw std::invalid_argument(triangles + "[" + std::to_string(i) + "]: vertex index " + std::to_string(largest) +
                                        " is out of range (" + std::to_string(mesh.positions.size()) + " vertices)");
        mesh.triangles[i] = f;
    }
    mesh.objects.push_back({"", 0, uint32_t(mesh.triangles.size())});
    return mesh;
}

Instance to_instance(const MeshInstance& instance, size_t index, size_t meshes) {
    const std::string name = "instances[" + std::to_string(index) + "]";
    if (instance.mesh >= meshes)
        throw std::invalid_argument(name + ".mesh: " + std::to_string(instance.mesh) + " is out of range (" +
                                    std::to_string(meshes) + " meshes)");
    Instance out{instance.mesh, glm::mat4(1.0f)};
    for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 4; ++col) {
            const float value = instance.transform[4 * row + col];
            if (!std::isfinite(value)) throw std::invalid_argument(name + ".transform: " + describe(value) + " in it");
            out.transform[col][row] = value;  // glm: [column][row]
        }
    if (glm::determinant(glm::mat3(out.transform)) == 0.0f) throw std::invalid_argument(name + ".transform: singular");
    return out;
}

Scene to_scene(std::span<const MeshArrays> meshes, std::span<const MeshInstance> instances, bool one_mesh) {
    if (meshes.empty()) throw std::invalid_argument("meshes: empty");
    Scene scene;
    scene.name = "arrays";
    for (size_t m = 0; m < meshes.size(); ++m)
        scene.meshes.push_back(to_mesh(meshes[m], one_mesh ? "" : "meshes[" + std::to_string(m) + "]."));
    for (size_t i = 0; i < instances.size(); ++i) scene.instances.push_back(to_instance(instances[i], i, meshes.size()));
    if (instances.empty())
        for (uint32_t m = 0; m < meshes.size(); ++m) scene.instances.push_back({m, glm::mat4(1.0f)});
    if (instanced_triangle_count(scene) >= kNoHit)
        throw std::invalid_argument("instances: more than 2^32 - 2 triangles in the world");
    return scene;
}

CanopyOptions engine_options(const AccelOptions& options) {
    if (options.builder != "auto") naming("builder", [&] { check_builder_name(options.builder); });
    naming("kernel", [&] { kernel_width(options.kernel); });
    if (options.toplevel != "flat" && options.toplevel != "two-level" && options.toplevel != "rebraid")
        throw std::invalid_argument("toplevel: unknown '" + options.toplevel + "' (known: flat, two-level, rebraid)");
    if (options.builder == "auto" && options.toplevel != "flat")
        throw std::invalid_argument("toplevel: builder 'auto' chooses the top level itself; leave it 'flat'");
    if (options.threads < 0) throw std::invalid_argument("threads: " + std::to_string(options.threads) + " (0 is all)");
    CanopyOptions engine;
    engine.layout = naming("layout", [&] { return parse_node_layout(options.layout); });
    engine.builder = options.builder;
    engine.kernel = options.kernel;
    engine.robust = options.robust;
    engine.watertight = options.watertight;
    engine.toplevel = options.toplevel;
    if (!options.collapse.empty()) engine.collapse = naming("collapse", [&] { return parse_collapse_method(options.collapse); });
    naming("collapse", [&] { check_collapse_options(engine); });
    naming("layout", [&] { check_node_layout_options(engine); });
    return engine;
}

void check_span(size_t size, size_t rays, const std::string& name) {
    if (size != 0 && size != rays)
        throw std::invalid_argument(name + ": " + std::to_string(size) + " values for " + std::to_string(rays) + " rays");
}

// The rays of a batch, after checking that its views agree.
size_t batch_size(const RayBatch& rays) {
    check_triples(rays.origins, "origins");
    check_triples(rays.directions, "directions");
    const size_t n = rays.origins.size() / 3;
    if (rays.directions.size() != rays.origins.size())
        throw std::invalid_argument("directions: " + std::to_string(rays.directions.size() / 3) + " rays, origins " +
                                    std::to_string(n));
    for (const auto& [span, name] : {std::pair{rays.tmin, "tmin"}, std::pair{rays.tmax, "tmax"}})
        if (span.size() > 1) check_span(span.size(), n, name);
    return n;
}

float interval_end(std::span<const float> values, size_t i, float otherwise) {
    return values.empty() ? otherwise : values.size() == 1 ? values[0] : values[i];
}

Ray batch_ray(const RayBatch& rays, size_t i) {
    return {{rays.origins[3 * i], rays.origins[3 * i + 1], rays.origins[3 * i + 2]},
            {rays.directions[3 * i], rays.directions[3 * i + 1], rays.directions[3 * i + 2]},
            interval_end(rays.tmin, i, 0.0f), interval_end(rays.tmax, i, kInfinity)};
}

enum class RayCheck { Valid, NonFinite, NegativeTmin };

// Finite origin and direction, tmin and tmax not NaN, tmin not negative: what a query asks of a ray.
RayCheck check_values(const RayBatch& rays, size_t i) {
    bool finite = true;
    for (size_t k = 3 * i; k < 3 * i + 3; ++k) finite &= std::isfinite(rays.origins[k]) && std::isfinite(rays.directions[k]);
    const float tmin = interval_end(rays.tmin, i, 0.0f);
    if (!finite || std::isnan(tmin) || std::isnan(interval_end(rays.tmax, i, 0.0f))) return RayCheck::NonFinite;
    return tmin < 0.0f ? RayCheck::NegativeTmin : RayCheck::Valid;
}

// Throws an invalid_argument naming the first value that makes ray i invalid.
void check_ray(const RayBatch& rays, size_t i) {
    const RayCheck check = check_values(rays, i);
    if (check == RayCheck::Valid) return;
    const auto name = [&](std::span<const float> values, const std::string& what) {
        return values.size() == 1 ? what : what + "[" + std::to_string(i) + "]";
    };
    if (check == RayCheck::NegativeTmin)
        throw std::invalid_argument(name(rays.tmin, "tmin") + ": " + std::to_string(interval_end(rays.tmin, i, 0.0f)) +
                                    " is negative (hits lie in (tmin, tmax], tmin >= 0)");
    check_finite_xyz(rays.origins.subspan(3 * i, 3), "origins", i);
    check_finite_xyz(rays.directions.subspan(3 * i, 3), "directions", i);
    throw std::invalid_argument(std::isnan(interval_end(rays.tmin, i, 0.0f)) ? name(rays.tmin, "tmin") + ": nan" : name(rays.tmax, "tmax") + ": nan");
}

// A ray that can hit nothing, standing in for an invalid one answered as a miss: its interval (0, 0] is empty.
constexpr Ray kMissRay{{0.0f, 0.0f, 0.0f}, {1.0f, 0.0f, 0.0f}, 0.0f, 0.0f};

// t as a float inside the ray's interval (tmin, tmax].
float interval_t(double t, const Ray& ray) {
    const float lowest = std::nextafter(kernel_tmin(ray), kInfinity);
    return std::clamp(float(t), lowest, std::max(lowest, ray.tmax));
}

DVec3 unit_normal(const Triangle& t) {
    const DVec3 v0(t.v0);
    const DVec3 n = glm::cross(DVec3(t.v1) - v0, DVec3(t.v2) - v0);
    const double length = glm::length(n);
    return length > 0.0 ? n / length : DVec3(0.0);
}

// One flat tree of standard nodes bound to its kernel, the layout the ray-list and point queries walk.
template <class Kernel>
struct FlatKernel : std::false_type {};
template <int N, bool Robust, class Test>
struct FlatKernel<BvhKernel<WideBvh<N>, Robust, Test>> : std::true_type {};

// Rays or points a task of a batch takes at once.
constexpr size_t kQueryChunk = 256;

}  // namespace

struct Accel::Impl {
    Scene scene;
    FlatScene flat;  // world triangles: what flat builds build, auto's statistics and precise distances read
    std::vector<uint32_t> instance_first;  // each instance's first triangle in flat's order (flatten's)
    std::unique_ptr<Accelerator> accelerator;
    mutable tbb::task_arena arena;
    double build_ms = 0;
    float largest_coordinate = 0;  // of the world's triangles: what the kernel's distance errors scale with

    Impl(Scene&& scene_in, const AccelOptions& options) : scene(std::move(scene_in)) {
        const CanopyOptions engine = engine_options(options);
        arena.initialize(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
        uint32_t first = 0;
        for (const Instance& instance : scene.instances) {
            instance_first.push_back(first);
            first += uint32_t(scene.meshes[instance.mesh].triangles.size());
        }
        arena.execute([&] {
            flat = flatten(scene);
            accelerator = make_canopy_accelerator(scene, flat, engine);
            const auto start = std::chrono::steady_clock::now();
            accelerator->prepare();
            accelerator->build();
            build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        });
        const Vec3 corner = glm::max(glm::abs(flat.bounds.lower), glm::abs(flat.bounds.upper));
        largest_coordinate = std::max({corner.x, corner.y, corner.z});
    }

    // The ray the kernel traces for a query's ray: its interval reaches past tmax by a bound on the kernel's error
    // in t, 2^-18 (32 float spacings) of the largest coordinate relative to the origin over the direction's largest
    // component, a few times the largest error measured (docs/results.md#precise-distances-for-short-hits); precise
    // distances then decide what lies in (tmin, tmax].
    Ray kernel_ray(const Ray& ray) const {
        Ray wider = ray;
        if (!std::isinf(ray.tmax)) wider.tmax = ray.tmax + kernel_t_error(ray);
        return wider;
    }
    float kernel_t_error(const Ray& ray) const {
        const float reach = largest_coordinate + std::max({std::abs(ray.org.x), std::abs(ray.org.y), std::abs(ray.org.z)});
        const float dir = std::max({std::abs(ray.dir.x), std::abs(ray.dir.y), std::abs(ray.dir.z)});
        return 0x1p-18f * reach / dir;
    }
    // Whether a kernel's hit at t lies in the ray's interval whatever its precise distance: farther than the
    // kernel's error from both ends.
    bool surely_inside(const Ray& ray, float t) const {
        const float error = kernel_t_error(ray);
        return t > kernel_tmin(ray) + error && t < ray.tmax - error;
    }

    // The instance of a flat triangle, and the triangle's index in its mesh.
    std::pair<uint32_t, uint32_t> placed(uint32_t prim) const {
        const size_t instance = std::upper_bound(instance_first.begin(), instance_first.end(), prim) - instance_first.begin() - 1;
        return {uint32_t(instance), prim - instance_first[instance]};
    }

    RayHit to_public(const Hit& hit) const {
        if (!hit.found()) return {};
        const auto [instance, triangle] = placed(hit.prim);
        return {hit.t, hit.u, hit.v, triangle, instance};
    }

    // The kernel's closest hit of kernel_ray(ray), its distance made precise: a hit at t <= tmin on the exact plane
    // (an origin on the surface) does not count, and the ray goes on from there; one past tmax is a miss.
    Hit precise_closest(const Ray& ray, Hit hit) const {
        for (;;) {
            if (!hit.found()) return hit;
            const double t = precise_t(flat.triangles[hit.prim], ray);
            if (precise_hit_counts(t, kernel_tmin(ray))) {
                if (float(t) > ray.tmax) return Hit{};  // the distance reported is the float
                hit.t = interval_t(t, ray);
                return hit;
            }
            Ray traced = kernel_ray(ray);
            traced.tmin = hit.t;
            hit = accelerator->trace(traced);
        }
    }
    // The kernel's any hit of kernel_ray(ray) where its precise distance lies in (tmin, tmax]; otherwise (a rare
    // ray, whose hit lies on its origin or just past tmax) the closest hit decides.
    Hit precise_any(const Ray& ray, const Hit& hit) const {
        if (!hit.found() || surely_inside(ray, hit.t)) return hit;  // most hits: no read of the triangle
        const double t = precise_t(flat.triangles[hit.prim], ray);
        if (precise_hit_counts(t, kernel_tmin(ray)) && float(t) <= ray.tmax) return hit;
        return precise_closest(ray, accelerator->trace(kernel_ray(ray)));
    }

    // Converts, traces and hands each chunk of the batch to `write`(first ray, hits), on the arena's threads. An
    // invalid ray stops the batch with the error of the first one, or is a miss (rays.invalid_rays_miss).
    template <class Write>
    void trace(Query query, const RayBatch& rays, Write&& write) const {
        const size_t n = batch_size(rays);
        std::atomic<size_t> first_bad{n};
        arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kBatchChunk), [&](const tbb::blocked_range<size_t>& range) {
                Ray chunk_rays[kBatchChunk], traced[kBatchChunk];
                Hit chunk_hits[kBatchChunk];
                if (!convert(rays, range, chunk_rays, first_bad)) return;
                const size_t count = range.size();
                for (size_t k = 0; k < count; ++k) traced[k] = kernel_ray(chunk_rays[k]);
                accelerator->trace_batch(query, {traced, count}, {chunk_hits, count});
                // Closest hits' triangles, read for precise distances, fetched together so that their misses overlap.
                for (size_t k = 0; k < count && query == Query::Closest; ++k)
                    if (chunk_hits[k].found()) _mm_prefetch(reinterpret_cast<const char*>(&flat.triangles[chunk_hits[k].prim]), _MM_HINT_T0);
                for (size_t k = 0; k < count; ++k)
                    chunk_hits[k] = query == Query::Closest ? precise_closest(chunk_rays[k], chunk_hits[k]) : precise_any(chunk_rays[k], chunk_hits[k]);
                write(range.begin(), std::span<const Hit>(chunk_hits, count));
            }, tbb::simple_partitioner());
        });
        if (first_bad < n) check_ray(rays, first_bad);
    }

    // The rays of `range` into `out`; false, with first_bad lowered to it, at a ray the batch may not take.
    static bool convert(const RayBatch& rays, const tbb::blocked_range<size_t>& range, Ray* out, std::atomic<size_t>& first_bad) {
        for (size_t i = range.begin(); i < range.end(); ++i) {
            const RayCheck check = check_values(rays, i);
            if (check == RayCheck::Valid || (check == RayCheck::NonFinite && rays.invalid_rays_miss)) {
                out[i - range.begin()] = check == RayCheck::Valid ? batch_ray(rays, i) : kMissRay;
                continue;
            }
            for (size_t bad = first_bad; i < bad && !first_bad.compare_exchange_weak(bad, i);) {}
            return false;
        }
        return true;
    }

    // Calls f(kernel) with the flat tree's kernel, or throws naming the query when the tree is of another layout.
    template <class F>
    void with_flat_kernel(const char* query, F&& f) const {
        const auto refuse = [&] {
            throw std::invalid_argument(std::string(query) + ": needs a flat tree of standard nodes (toplevel 'flat', layout "
                                        "'standard', a builder other than 'kdtree'); this one is " + accelerator->kernel());
        };
        with_kernel(accelerator->bound_kernel(), [&]<class Kernel>(const Kernel& kernel) {
            if constexpr (FlatKernel<Kernel>::value) f(kernel);
            else refuse();
        }, refuse);
    }

    // Each distinct triangle the ray hits, with precise distances, ordered by t then triangle.
    template <bool Robust, class Test, int N>
    void all_hits(const WideBvh<N>& bvh, const Ray& ray, std::vector<Hit>& out) const {
        out.clear();
        for_each_hit<Robust, Test>(bvh, kernel_ray(ray), [&](Hit hit, const Triangle& corners) {
            const double t = precise_t(corners, ray);
            if (!precise_hit_counts(t, kernel_tmin(ray)) || float(t) > ray.tmax) return;
            hit.t = interval_t(t, ray);
            out.push_back(hit);
        });
        std::sort(out.begin(), out.end(), [](const Hit& a, const Hit& b) { return a.t != b.t ? a.t < b.t : a.prim < b.prim; });
        out.erase(std::unique(out.begin(), out.end(), [](const Hit& a, const Hit& b) { return a.prim == b.prim; }), out.end());
    }

    // Runs per_chunk(kernel, first ray's index, rays) over the batch's chunks, rays [k kQueryChunk, (k + 1)
    // kQueryChunk), on the arena's threads; invalid rays as in trace.
    template <class PerChunk>
    void for_each_chunk(const char* query, const RayBatch& rays, PerChunk&& per_chunk) const {
        const size_t n = batch_size(rays);
        std::atomic<size_t> first_bad{n};
        with_flat_kernel(query, [&](const auto& kernel) {
            arena.execute([&] {
                tbb::parallel_for(size_t(0), (n + kQueryChunk - 1) / kQueryChunk, [&](size_t chunk) {
                    const tbb::blocked_range<size_t> range(chunk * kQueryChunk, std::min(n, (chunk + 1) * kQueryChunk));
                    Ray chunk_rays[kQueryChunk];
                    if (!convert(rays, range, chunk_rays, first_bad)) return;
                    per_chunk(kernel, range.begin(), std::span<const Ray>(chunk_rays, range.size()));
                });
            });
        });
        if (first_bad < n) check_ray(rays, first_bad);
    }

    // Runs per_point(kernel, index, point) for every point; a non-finite point throws naming it, or is passed on as
    // no point (invalid_points_miss).
    template <class PerPoint>
    void for_each_point(const char* query, std::span<const float> points, bool invalid_points_miss, PerPoint&& per_point) const {
        check_triples(points, "points");
        const size_t n = points.size() / 3;
        if (!invalid_points_miss) check_finite_xyz(points, "points");
        with_flat_kernel(query, [&](const auto& kernel) {
            arena.execute([&] {
                tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kQueryChunk), [&](const tbb::blocked_range<size_t>& range) {
                    for (size_t i = range.begin(); i < range.end(); ++i) {
                        const DVec3 p(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
                        per_point(kernel, i, std::isfinite(p.x + p.y + p.z) ? std::optional(p) : std::nullopt);
                    }
                });
            });
        });
    }
};

Accel::Accel(const MeshArrays& mesh, const AccelOptions& options)
    : impl_(std::make_unique<Impl>(to_scene({&mesh, 1}, {}, true), options)) {}

Accel::Accel(std::span<const MeshArrays> meshes, std::span<const MeshInstance> instances, const AccelOptions& options)
    : impl_(std::make_unique<Impl>(to_scene(meshes, instances, false), options)) {}

Accel::~Accel() = default;
Accel::Accel(Accel&&) noexcept = default;
Accel& Accel::operator=(Accel&&) noexcept = default;

RayHit Accel::intersect(const std::array<float, 3>& origin, const std::array<float, 3>& direction, float tmin, float tmax) const {
    const RayBatch one{origin, direction, {&tmin, 1}, {&tmax, 1}};
    check_ray(one, 0);
    const Ray ray = batch_ray(one, 0);
    return impl_->to_public(impl_->precise_closest(ray, impl_->accelerator->trace(impl_->kernel_ray(ray))));
}

bool Accel::occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction, float tmin, float tmax) const {
    const RayBatch one{origin, direction, {&tmin, 1}, {&tmax, 1}};
    check_ray(one, 0);
    const Ray ray = batch_ray(one, 0), traced = impl_->kernel_ray(ray);
    Hit hit;
    impl_->accelerator->trace_batch(Query::Any, {&traced, 1}, {&hit, 1});
    return impl_->precise_any(ray, hit).found();
}

void Accel::intersect(const RayBatch& rays, const HitBatch& hits) const {
    const size_t n = batch_size(rays);
    check_span(hits.t.size(), n, "hits.t");
    check_span(hits.triangle.size(), n, "hits.triangle");
    check_span(hits.u.size(), n, "hits.u");
    check_span(hits.v.size(), n, "hits.v");
    check_span(hits.instance.size(), n, "hits.instance");
    check_span(hits.normal.size() / 3, n, "hits.normal");
    if (hits.normal.size() % 3 != 0) check_triples(hits.normal, "hits.normal");
    impl_->trace(Query::Closest, rays, [&](size_t first, std::span<const Hit> chunk) {
        for (size_t k = 0; k < chunk.size(); ++k) {
            const RayHit hit = impl_->to_public(chunk[k]);
            const size_t i = first + k;
            if (!hits.t.empty()) hits.t[i] = hit.t;
            if (!hits.triangle.empty()) hits.triangle[i] = hit.triangle;
            if (!hits.u.empty()) hits.u[i] = hit.u;
            if (!hits.v.empty()) hits.v[i] = hit.v;
            if (!hits.instance.empty()) hits.instance[i] = hit.instance;
            if (hits.normal.empty()) continue;
            const DVec3 normal = chunk[k].found() ? unit_normal(impl_->flat.triangles[chunk[k].prim]) : DVec3(0.0);
            for (int a = 0; a < 3; ++a) hits.normal[3 * i + a] = float(normal[a]);
        }
    });
}

void Accel::occluded(const RayBatch& rays, std::span<bool> occluded) const {
    if (occluded.size() != batch_size(rays))
        throw std::invalid_argument("occluded: " + std::to_string(occluded.size()) + " values for " +
                                    std::to_string(batch_size(rays)) + " rays");
    impl_->trace(Query::Any, rays, [&](size_t first, std::span<const Hit> chunk) {
        for (size_t k = 0; k < chunk.size(); ++k) occluded[first + k] = chunk[k].found();
    });
}

void Accel::intersect_all(const RayBatch& rays, HitList& out) const {
    const size_t n = batch_size(rays);
    // Each chunk's hits go to a list of its own first; the flat arrays are written once their offsets are known.
    std::vector<std::vector<Hit>> chunks((n + kQueryChunk - 1) / kQueryChunk);
    out.offsets.assign(n + 1, 0);
    impl_->for_each_chunk("intersect_all", rays, [&]<class Kernel>(const Kernel& kernel, size_t first, std::span<const Ray> chunk) {
        std::vector<Hit>& list = chunks[first / kQueryChunk];
        std::vector<Hit> hits;
        for (size_t k = 0; k < chunk.size(); ++k) {
            impl_->all_hits<Kernel::kRobust, typename Kernel::Test>(kernel.bvh, chunk[k], hits);
            list.insert(list.end(), hits.begin(), hits.end());
            out.offsets[first + k + 1] = hits.size();
        }
    });
    for (size_t i = 0; i < n; ++i) out.offsets[i + 1] += out.offsets[i];
    const size_t total = out.offsets[n];
    out.t.resize(total), out.u.resize(total), out.v.resize(total), out.triangle.resize(total), out.instance.resize(total);
    size_t j = 0;
    for (const std::vector<Hit>& list : chunks)
        for (const Hit& h : list) {
            const RayHit hit = impl_->to_public(h);
            out.t[j] = hit.t, out.u[j] = hit.u, out.v[j] = hit.v, out.triangle[j] = hit.triangle, out.instance[j] = hit.instance;
            ++j;
        }
}

void Accel::count_hits(const RayBatch& rays, std::span<uint32_t> counts) const {
    if (counts.size() != batch_size(rays))
        throw std::invalid_argument("counts: " + std::to_string(counts.size()) + " values for " +
                                    std::to_string(batch_size(rays)) + " rays");
    impl_->for_each_chunk("count_hits", rays, [&]<class Kernel>(const Kernel& kernel, size_t first, std::span<const Ray> chunk) {
        std::vector<Hit> hits;
        for (size_t k = 0; k < chunk.size(); ++k) {
            impl_->all_hits<Kernel::kRobust, typename Kernel::Test>(kernel.bvh, chunk[k], hits);
            counts[first + k] = uint32_t(hits.size());
        }
    });
}

void Accel::closest_points(std::span<const float> points, const PointBatch& out, bool invalid_points_miss) const {
    const size_t n = points.size() / 3;
    check_span(out.point.size() / 3, n, "out.point");
    check_span(out.distance.size(), n, "out.distance");
    check_span(out.triangle.size(), n, "out.triangle");
    check_span(out.instance.size(), n, "out.instance");
    check_span(out.u.size(), n, "out.u");
    check_span(out.v.size(), n, "out.v");
    impl_->for_each_point("closest_points", points, invalid_points_miss, [&](const auto& kernel, size_t i, std::optional<DVec3> p) {
        const PointHit hit = p ? closest_point(kernel.bvh, *p) : PointHit{};
        const auto [instance, triangle] = hit.found() ? impl_->placed(hit.prim) : std::pair{kNoHit, kNoHit};
        const float nan = std::numeric_limits<float>::quiet_NaN();
        if (!out.point.empty())
            for (int a = 0; a < 3; ++a) out.point[3 * i + a] = hit.found() ? float(hit.point[a]) : nan;
        if (!out.distance.empty()) out.distance[i] = float(std::sqrt(hit.distance2));
        if (!out.triangle.empty()) out.triangle[i] = triangle;
        if (!out.instance.empty()) out.instance[i] = instance;
        if (!out.u.empty()) out.u[i] = float(hit.u);
        if (!out.v.empty()) out.v[i] = float(hit.v);
    });
}

void Accel::contains(std::span<const float> points, std::span<bool> inside, bool invalid_points_miss) const {
    if (inside.size() != points.size() / 3)
        throw std::invalid_argument("inside: " + std::to_string(inside.size()) + " values for " + std::to_string(points.size() / 3) + " points");
    // Three directions of no symmetry of a mesh's axes or grids, so no two graze the same edge.
    static const std::array<Vec3, 3> kDirections{glm::normalize(Vec3(0.5443f, 0.7113f, 0.4452f)),
                                                 glm::normalize(Vec3(-0.6531f, 0.3142f, 0.6892f)),
                                                 glm::normalize(Vec3(0.2718f, -0.8413f, -0.4671f))};
    impl_->for_each_point("contains", points, invalid_points_miss, [&]<class Kernel>(const Kernel& kernel, size_t i, std::optional<DVec3> p) {
        thread_local std::vector<Hit> hits;
        int odd = 0, even = 0;
        for (size_t k = 0; p && k < kDirections.size() && odd < 2 && even < 2; ++k) {  // two agreeing decide
            impl_->all_hits<Kernel::kRobust, typename Kernel::Test>(kernel.bvh, Ray{Vec3(*p), kDirections[k]}, hits);
            (hits.size() % 2 ? odd : even) += 1;
        }
        inside[i] = odd >= 2;
    });
}

void Accel::check_rays(const RayBatch& rays) {
    const size_t n = batch_size(rays);
    for (size_t i = 0; i < n; ++i) {
        const RayCheck check = check_values(rays, i);
        if (check != RayCheck::Valid && !(check == RayCheck::NonFinite && rays.invalid_rays_miss)) check_ray(rays, i);
    }
}

AccelStats Accel::stats(bool with_epo) const {
    const Accelerator& a = *impl_->accelerator;
    const AcceleratorReport r = impl_->arena.execute([&] { return a.report(with_epo); });
    AccelStats s;
    s.builder = a.builder() == "auto" ? a.chosen() : a.builder();
    s.kernel = a.kernel();
    s.reason = a.reason();
    s.triangles = impl_->flat.triangles.size();
    s.build_ms = impl_->build_ms;
    s.sah = r.sah, s.epo = r.epo, s.layout_sah = r.layout_sah;
    s.nodes = r.nodes, s.leaves = r.leaves, s.depth = r.depth;
    s.references_per_triangle = r.refs_per_tri;
    s.bytes = r.bytes.value_or(0);
    return s;
}

std::vector<BuilderDescription> registered_builders() {
    std::vector<BuilderDescription> out;
    for (const BuilderName& entry : all_builders()) {
        BuilderDescription& d = out.emplace_back(BuilderDescription{entry.name, entry.description, {}});
        if (!is_bvh_builder(entry.name)) continue;
        for (const BuilderParam& p : find_builder(entry.name).params) d.params.push_back({p.key, p.default_value, p.help});
    }
    return out;
}

TriangleMesh load_triangles(const std::string& path) {
    FlatScene flat;
    try {
        flat = flatten(load_scene(path));
    } catch (const InputError& e) {
        throw std::invalid_argument(e.what());
    }
    TriangleMesh mesh;
    mesh.vertices.reserve(flat.triangles.size() * 9);
    for (const Triangle& t : flat.triangles)
        for (const Vec3& p : {t.v0, t.v1, t.v2}) mesh.vertices.insert(mesh.vertices.end(), {p.x, p.y, p.z});
    mesh.triangles.resize(flat.triangles.size() * 3);
    for (uint32_t i = 0; i < mesh.triangles.size(); ++i) mesh.triangles[i] = i;
    return mesh;
}

}  // namespace canopy
