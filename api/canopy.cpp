// The public API over the engine: input arrays become a Scene (meshes, instances) and its flattened world
// triangles, from which make_canopy_accelerator() builds as `canopy render` and `canopy bench` do; queries go to
// the accelerator's single-ray kernel or its batch kernel, batches split across the accelerator's threads.
#include "canopy/canopy.h"

#include "accel/builder.h"
#include "kernels/dispatch.h"
#include "engine/accelerator.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
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

// Finite origin and direction, tmin and tmax not NaN: what a query asks of a ray.
bool valid_ray(const RayBatch& rays, size_t i) {
    bool finite = true;
    for (size_t k = 3 * i; k < 3 * i + 3; ++k) finite &= std::isfinite(rays.origins[k]) && std::isfinite(rays.directions[k]);
    return finite && !std::isnan(interval_end(rays.tmin, i, 0.0f)) && !std::isnan(interval_end(rays.tmax, i, 0.0f));
}

// Throws an invalid_argument naming the first value that makes ray i invalid.
void check_ray(const RayBatch& rays, size_t i) {
    if (valid_ray(rays, i)) return;
    const std::string index = "[" + std::to_string(i) + "]";
    check_finite_xyz(rays.origins.subspan(3 * i, 3), "origins", i);
    check_finite_xyz(rays.directions.subspan(3 * i, 3), "directions", i);
    throw std::invalid_argument(std::isnan(interval_end(rays.tmin, i, 0.0f)) ? (rays.tmin.size() == 1 ? "tmin: nan" : "tmin" + index + ": nan")
                                                                          : (rays.tmax.size() == 1 ? "tmax: nan" : "tmax" + index + ": nan"));
}

}  // namespace

struct Accel::Impl {
    Scene scene;
    FlatScene flat;  // world triangles: what flat builds build and auto's statistics read
    std::vector<uint32_t> instance_first;  // each instance's first triangle in flat's order (flatten's)
    std::unique_ptr<Accelerator> accelerator;
    mutable tbb::task_arena arena;
    double build_ms = 0;

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
    }

    RayHit to_public(const Hit& hit) const {
        if (!hit.found()) return {};
        const size_t instance = std::upper_bound(instance_first.begin(), instance_first.end(), hit.prim) - instance_first.begin() - 1;
        return {hit.t, hit.u, hit.v, hit.prim - instance_first[instance], uint32_t(instance)};
    }

    // Converts, traces and hands each chunk of the batch to `write`(first ray, hits), on the arena's threads.
    // An invalid ray stops the batch with the error of the first one.
    template <class Write>
    void trace(Query query, const RayBatch& rays, Write&& write) const {
        const size_t n = batch_size(rays);
        std::atomic<size_t> first_bad{n};
        arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kBatchChunk), [&](const tbb::blocked_range<size_t>& range) {
                Ray chunk_rays[kBatchChunk];
                Hit chunk_hits[kBatchChunk];
                for (size_t i = range.begin(); i < range.end(); ++i) {
                    if (!valid_ray(rays, i)) {
                        for (size_t bad = first_bad; i < bad && !first_bad.compare_exchange_weak(bad, i);) {}
                        return;
                    }
                    chunk_rays[i - range.begin()] = batch_ray(rays, i);
                }
                const size_t count = range.size();
                accelerator->trace_batch(query, {chunk_rays, count}, {chunk_hits, count});
                write(range.begin(), std::span<const Hit>(chunk_hits, count));
            }, tbb::simple_partitioner());
        });
        if (first_bad < n) check_ray(rays, first_bad);
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
    return impl_->to_public(impl_->accelerator->trace(batch_ray(one, 0)));
}

bool Accel::occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction, float tmin, float tmax) const {
    const RayBatch one{origin, direction, {&tmin, 1}, {&tmax, 1}};
    check_ray(one, 0);
    const Ray ray = batch_ray(one, 0);
    Hit hit;
    impl_->accelerator->trace_batch(Query::Any, {&ray, 1}, {&hit, 1});
    return hit.found();
}

void Accel::intersect(const RayBatch& rays, const HitBatch& hits) const {
    const size_t n = batch_size(rays);
    check_span(hits.t.size(), n, "hits.t");
    check_span(hits.triangle.size(), n, "hits.triangle");
    check_span(hits.u.size(), n, "hits.u");
    check_span(hits.v.size(), n, "hits.v");
    check_span(hits.instance.size(), n, "hits.instance");
    impl_->trace(Query::Closest, rays, [&](size_t first, std::span<const Hit> chunk) {
        for (size_t k = 0; k < chunk.size(); ++k) {
            const RayHit hit = impl_->to_public(chunk[k]);
            const size_t i = first + k;
            if (!hits.t.empty()) hits.t[i] = hit.t;
            if (!hits.triangle.empty()) hits.triangle[i] = hit.triangle;
            if (!hits.u.empty()) hits.u[i] = hit.u;
            if (!hits.v.empty()) hits.v[i] = hit.v;
            if (!hits.instance.empty()) hits.instance[i] = hit.instance;
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
