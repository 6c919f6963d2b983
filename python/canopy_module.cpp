// The Python module `canopy`: numpy arrays in and out of the public C++ API (include/canopy/canopy.h). Arrays of
// the API's own types and layout (float32 and uint32, C order) are read in place; others are converted once. The
// GIL is released while an accelerator builds and while a batch is traced. Bad input raises ValueError naming the
// argument: shapes and types are checked here, values (NaN, indices) by the C++ API, whose std::invalid_argument
// pybind11 turns into ValueError.
#include <canopy/canopy.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <type_traits>

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

std::string shape_of(const py::array& a) {
    std::string s = "(";
    for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
    return s + (a.ndim() == 1 ? ",)" : ")");
}

py::array as_array(const py::object& object, const std::string& name) {
    py::array a = py::array::ensure(object);
    if (!a) throw py::value_error(name + ": not an array of numbers");
    return a;
}

// `a` as a C-order array of T, in place when it is one, else converted; numpy's ensure returns nothing when it cannot
// (a copy too large for memory), which raises a ValueError naming the argument.
template <class T>
py::array_t<T, py::array::c_style> converted(const py::array& a, const std::string& name) {
    auto out = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(a);
    if (!out)
        throw py::value_error(name + ": cannot allocate a C-order " + std::string(py::str(py::dtype::of<T>())) + " copy of shape " +
                              shape_of(a));
    return out;
}

enum class Rows { AtLeastOne, AnyNumber };

// `object` as a C-order float32 array of shape (n, 3), or (n, 3, 4) for ndim 3: in place when it is one, else a
// converted copy. A ray batch may be empty (it then does nothing, as in the C++ API); a mesh may not.
py::array_t<float, py::array::c_style> float_array(const py::object& object, const std::string& name, py::ssize_t ndim = 2,
                                                   Rows rows = Rows::AtLeastOne) {
    const py::array a = as_array(object, name);
    const std::string expected = ndim == 2 ? "(n, 3)" : "(n, 3, 4)";
    const bool shaped = a.ndim() == ndim && a.shape(1) == 3 && (ndim == 2 || a.shape(2) == 4);
    if (!shaped) throw py::value_error(name + ": shape " + shape_of(a) + ", expected " + expected);
    const char kind = a.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u')
        throw py::value_error(name + ": dtype " + std::string(py::str(a.dtype())) + ", expected float32 (or real numbers, converted)");
    if (a.shape(0) == 0 && rows == Rows::AtLeastOne) throw py::value_error(name + ": empty");
    return converted<float>(a, name);
}

// Range checks of indices that are not uint32, before the conversion to uint32 would wrap them. Messages as the C++
// API's, which checks uint32 indices.
template <class Int>
void check_indices(const py::array& a, const std::string& name, size_t vertices) {
    const auto typed = converted<Int>(a, name);
    const Int* data = typed.data();
    for (py::ssize_t i = 0; i < typed.size(); ++i) {
        const std::string index = name + "[" + std::to_string(i / 3) + "]: vertex index " + std::to_string(data[i]);
        if constexpr (std::is_signed_v<Int>)
            if (data[i] < 0) throw py::value_error(index + " is negative");
        if (uint64_t(data[i]) >= vertices)
            throw py::value_error(index + " is out of range (" + std::to_string(vertices) + " vertices)");
    }
}

// `object` as C-order uint32 triangles of shape (m, 3): in place for uint32, and for int32 (the same bits when no
// index is negative), else converted.
py::array index_array(const py::object& object, const std::string& name, size_t vertices) {
    const py::array a = as_array(object, name);
    if (a.ndim() != 2 || a.shape(1) != 3) throw py::value_error(name + ": shape " + shape_of(a) + ", expected (m, 3)");
    const char kind = a.dtype().kind();
    if (kind != 'i' && kind != 'u')
        throw py::value_error(name + ": dtype " + std::string(py::str(a.dtype())) + ", expected uint32 (or integers, converted)");
    if (a.shape(0) == 0) throw py::value_error(name + ": empty");
    const bool in_place = a.itemsize() == 4 && (a.flags() & py::array::c_style);
    if (kind == 'u' && in_place) return a;
    if (kind == 'i' && in_place) {
        check_indices<int32_t>(a, name, vertices);
        return a.attr("view")(py::dtype::of<uint32_t>());
    }
    if (kind == 'i') check_indices<int64_t>(a, name, vertices);
    else check_indices<uint64_t>(a, name, vertices);
    return converted<uint32_t>(a, name);
}

std::span<const float> floats(const py::array_t<float, py::array::c_style>& a) { return {a.data(), size_t(a.size())}; }

// tmin or tmax: a number for every ray, or an array of one a ray.
py::array_t<float, py::array::c_style> interval_ends(const py::object& object, py::ssize_t rays, const std::string& name) {
    const py::array a = as_array(object, name);
    const char kind = a.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u')
        throw py::value_error(name + ": dtype " + std::string(py::str(a.dtype())) + ", expected a number or float32 array");
    if (a.ndim() > 1 || (a.ndim() == 1 && a.shape(0) != rays))
        throw py::value_error(name + ": shape " + shape_of(a) + ", expected a number or (" + std::to_string(rays) + ",)");
    return converted<float>(a, name);
}

// Runs f, turning a failed allocation (numpy's MemoryError or std::bad_alloc) into a ValueError naming the
// argument whose array could not be made.
template <class F>
auto allocating(const std::string& name, py::ssize_t count, const char* unit, F&& f) {
    const auto fail = [&] {
        return py::value_error(name + ": cannot allocate the arrays of " + std::to_string(count) + " " + unit);
    };
    try {
        return f();
    } catch (const std::bad_alloc&) {
        throw fail();
    } catch (py::error_already_set& e) {
        if (e.matches(PyExc_MemoryError)) throw fail();
        throw;
    }
}

// `object` as C-order float32 of shape (..., width), converted when it is not (float64 costs one conversion pass).
// Returns the array as (n, width) and the batch's shape (...).
std::pair<py::array_t<float, py::array::c_style>, std::vector<py::ssize_t>> batch_array(const py::object& object,
                                                                                         const std::string& name, py::ssize_t width) {
    const py::array a = as_array(object, name);
    if (a.ndim() < 1 || a.shape(a.ndim() - 1) != width)
        throw py::value_error(name + ": shape " + shape_of(a) + ", expected (..., " + std::to_string(width) + ")");
    const char kind = a.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u')
        throw py::value_error(name + ": dtype " + std::string(py::str(a.dtype())) + ", expected float32 or float64");
    std::vector<py::ssize_t> shape(a.shape(), a.shape() + a.ndim() - 1);
    const py::ssize_t count = a.size() / width;
    return {converted<float>(converted<float>(a, name).reshape({count, width}), name), shape};
}

// tmin or tmax of a batch of shape (...): a number for every ray, or an array of that shape.
py::array_t<float, py::array::c_style> batch_interval(const py::object& object, const std::vector<py::ssize_t>& shape,
                                                      const std::string& name) {
    const py::array a = as_array(object, name);
    const char kind = a.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u')
        throw py::value_error(name + ": dtype " + std::string(py::str(a.dtype())) + ", expected a number or float32 array");
    if (a.ndim() == 0) return converted<float>(a, name);
    if (!std::equal(shape.begin(), shape.end(), a.shape(), a.shape() + a.ndim()) || py::ssize_t(shape.size()) != a.ndim()) {
        py::tuple expected(shape.size());
        for (size_t d = 0; d < shape.size(); ++d) expected[d] = shape[d];
        throw py::value_error(name + ": shape " + shape_of(a) + ", expected a number or " + std::string(py::str(expected)));
    }
    return converted<float>(a.attr("reshape")(-1), name);
}

// Runs f without the GIL; a std::invalid_argument it throws becomes a ValueError with the message name(what()).
template <class F, class Name>
void without_gil(F&& f, Name&& name) {
    try {
        py::gil_scoped_release unlocked;
        f();
    } catch (const std::invalid_argument& e) {
        throw py::value_error(name(e.what()));
    }
}

// A batch's rays as the C++ API takes them, kept alive while its views refer to them: (..., 6) rays split into
// origins and directions, or separate (..., 3) origins and directions.
struct RayArgs {
    py::array_t<float, py::array::c_style> origins, directions, tmin, tmax;
    std::vector<py::ssize_t> shape;
    py::ssize_t count = 0;
    bool packed = false;  // given as (..., 6) rays: errors name `rays`

    RayArgs(const py::object& rays, const py::object& dirs, const py::object& t0, const py::object& t1) {
        if (dirs.is_none()) {
            packed = true;
            auto [both, batch_shape] = batch_array(rays, "rays", 6);
            shape = batch_shape;
            count = both.shape(0);
            allocating("rays", count, "rays", [&] {
                origins = py::array_t<float, py::array::c_style>({count, py::ssize_t(3)});
                directions = py::array_t<float, py::array::c_style>({count, py::ssize_t(3)});
            });
            const float* in = both.data();
            float *o = origins.mutable_data(), *d = directions.mutable_data();
            py::gil_scoped_release unlocked;
            for (py::ssize_t i = 0; i < count; ++i)
                for (int a = 0; a < 3; ++a) o[3 * i + a] = in[6 * i + a], d[3 * i + a] = in[6 * i + 3 + a];
        } else {
            std::tie(origins, shape) = batch_array(rays, "origins", 3);
            std::vector<py::ssize_t> direction_shape;
            std::tie(directions, direction_shape) = batch_array(dirs, "directions", 3);
            count = origins.shape(0);
            if (direction_shape != shape)
                throw py::value_error("directions: " + std::to_string(directions.shape(0)) + " rays, origins " + std::to_string(count));
        }
        tmin = batch_interval(t0, shape, "tmin");
        tmax = batch_interval(t1, shape, "tmax");
    }
    canopy::RayBatch batch(bool strict) const {
        return {floats(origins), floats(directions), floats(tmin), floats(tmax), !strict};
    }
    // A C++ error about origins[i] or directions[i] named as the Python argument: rays[i] for (..., 6) batches.
    std::string python_name(std::string message) const {
        if (!packed) return message;
        for (const char* field : {"origins", "directions"})
            if (message.rfind(field, 0) == 0) return "rays" + message.substr(std::string(field).size());
        return message;
    }
    template <class F>
    void run(F&& f) const {
        without_gil(f, [&](std::string message) { return python_name(std::move(message)); });
    }
};

// Output arrays of a batch's shape (...), with `extra` trailing dimensions.
template <class T>
py::array_t<T> batch_output(const std::vector<py::ssize_t>& shape, std::initializer_list<py::ssize_t> extra = {}) {
    std::vector<py::ssize_t> full = shape;
    full.insert(full.end(), extra);
    return py::array_t<T>(full);
}
template <class T>
std::span<T> span_of(py::array_t<T>& a) { return {a.mutable_data(), size_t(a.size())}; }
std::span<uint32_t> ids_of(py::array_t<int32_t>& a) { return {reinterpret_cast<uint32_t*>(a.mutable_data()), size_t(a.size())}; }

// A batch's input arrays, kept alive while the batch refers to them.
struct Rays {
    py::array_t<float, py::array::c_style> origins, directions, tmin, tmax;
    py::ssize_t count = 0;

    Rays(const py::object& o, const py::object& d, const py::object& t0, const py::object& t1)
        : origins(float_array(o, "origins", 2, Rows::AnyNumber)), directions(float_array(d, "directions", 2, Rows::AnyNumber)) {
        count = origins.shape(0);
        if (directions.shape(0) != count)
            throw py::value_error("directions: " + std::to_string(directions.shape(0)) + " rays, origins " + std::to_string(count));
        tmin = interval_ends(t0, count, "tmin");
        tmax = interval_ends(t1, count, "tmax");
    }
    canopy::RayBatch batch(bool strict) const { return {floats(origins), floats(directions), floats(tmin), floats(tmax), !strict}; }
};

// Vertices and triangles checked here, so that errors name the Python arguments (the C++ API would name
// meshes[i]): finite coordinates, indices in range.
void check_mesh(const py::array_t<float, py::array::c_style>& vertices, const py::array& triangles) {
    const float* v = vertices.data();
    for (py::ssize_t i = 0; i < vertices.size(); ++i)
        if (!std::isfinite(v[i]))
            throw py::value_error("vertices[" + std::to_string(i / 3) + "]: " + "xyz"[i % 3] + " is " +
                                  (std::isnan(v[i]) ? "nan" : v[i] > 0 ? "inf" : "-inf"));
    if (triangles.dtype().kind() == 'u' && triangles.itemsize() == 4) check_indices<uint32_t>(triangles, "triangles", size_t(vertices.shape(0)));
}

std::unique_ptr<canopy::Accel> make_accel(const py::object& vertices, const py::object& triangles, const std::string& builder,
                                          const std::string& kernel, bool robust, bool watertight, int threads,
                                          const py::object& instances, const std::string& toplevel, const std::string& layout,
                                          const std::string& collapse) {
    const auto v = float_array(vertices, "vertices");
    const py::array t = index_array(triangles, "triangles", size_t(v.shape(0)));
    check_mesh(v, t);
    const canopy::MeshArrays mesh{floats(v), {static_cast<const uint32_t*>(t.data()), size_t(t.size())}};
    std::vector<canopy::MeshInstance> placed;
    if (!instances.is_none()) {
        const auto transforms = float_array(instances, "instances", 3);
        placed.resize(transforms.shape(0));
        for (size_t i = 0; i < placed.size(); ++i) std::memcpy(placed[i].transform.data(), transforms.data(i), 12 * sizeof(float));
    }
    const canopy::AccelOptions options{builder, kernel, robust, watertight, toplevel, threads, layout, collapse};
    py::gil_scoped_release unlocked;
    try {
        return std::make_unique<canopy::Accel>(std::span(&mesh, 1), placed, options);
    } catch (const std::invalid_argument&) {
        throw;
    } catch (const std::exception& e) {  // a scene the builders cannot take (its extent, say) is bad input too
        throw std::invalid_argument(std::string("vertices: ") + e.what());
    }
}

py::tuple intersect(const canopy::Accel& accel, const py::object& origins, const py::object& directions, const py::object& tmin,
                    const py::object& tmax, bool with_instance, bool strict) {
    const Rays rays(origins, directions, tmin, tmax);
    py::array_t<float> t(rays.count), u(rays.count), v(rays.count);
    py::array_t<int32_t> triangle(rays.count), instance(with_instance ? rays.count : 0);
    // Misses are kNoHit, 0xffffffff: -1 in the int32 arrays Python gets.
    const canopy::HitBatch hits{span_of(t), ids_of(triangle), span_of(u), span_of(v), ids_of(instance), {}};
    {
        py::gil_scoped_release unlocked;
        accel.intersect(rays.batch(strict), hits);
    }
    return with_instance ? py::make_tuple(t, triangle, u, v, instance) : py::make_tuple(t, triangle, u, v);
}

py::array_t<bool> occluded(const canopy::Accel& accel, const py::object& origins, const py::object& directions,
                           const py::object& tmin, const py::object& tmax, bool strict) {
    const Rays rays(origins, directions, tmin, tmax);
    py::array_t<bool> out(rays.count);
    const std::span<bool> view(out.mutable_data(), size_t(rays.count));
    py::gil_scoped_release unlocked;
    accel.occluded(rays.batch(strict), view);
    return out;
}

// The accelerator over a scene's meshes as they were at a query, and the geometry id of each of its instances (the
// meshes with triangles, in order). Null accel: no triangles.
struct BuiltScene {
    std::unique_ptr<canopy::Accel> accel;
    std::vector<int32_t> geometry;

    // Instance numbers of the C++ API as geometry ids, in place.
    void to_geometry(py::array_t<int32_t>& ids) const {
        int32_t* p = ids.mutable_data();
        for (py::ssize_t i = 0; i < ids.size(); ++i) p[i] = p[i] < 0 ? -1 : geometry[size_t(p[i])];
    }
};

// A scene of several meshes, each with its geometry id (the order of add_mesh), built at its first query after a
// change. Meshes without triangles take an id and build nothing; a scene without triangles misses every ray. Its
// methods run with the GIL held and builds without it; a query keeps the build it started with, so add_mesh from
// another thread meanwhile changes the next query's answers, never the running one's.
class Scene {
public:
    explicit Scene(canopy::AccelOptions options) : options_(std::move(options)) {}

    int add_mesh(const py::object& vertices, const py::object& triangles) {
        const py::array t = as_array(triangles, "triangles");
        const bool empty = t.ndim() == 2 && t.shape(0) == 0 && t.shape(1) == 3;
        auto mesh = std::make_shared<Mesh>();
        if (!empty) {
            const auto v = float_array(vertices, "vertices");
            const py::array checked = index_array(t, "triangles", size_t(v.shape(0)));
            check_mesh(v, checked);
            const auto indices = converted<uint32_t>(checked, "triangles");
            mesh->vertices.assign(v.data(), v.data() + v.size());
            mesh->triangles.assign(indices.data(), indices.data() + indices.size());
        }
        meshes_.push_back(std::move(mesh));
        built_.reset();
        return int(meshes_.size() - 1);
    }

    // The build of the meshes added so far, made now if a mesh was added since the last one.
    std::shared_ptr<const BuiltScene> built() {
        if (built_) return built_;
        const std::vector<std::shared_ptr<const Mesh>> meshes = meshes_;  // alive while the GIL is released
        auto built = std::make_shared<BuiltScene>();
        std::vector<canopy::MeshArrays> arrays;
        for (size_t id = 0; id < meshes.size(); ++id) {
            if (meshes[id]->triangles.empty()) continue;
            arrays.push_back({meshes[id]->vertices, meshes[id]->triangles});
            built->geometry.push_back(int32_t(id));
        }
        if (!arrays.empty()) {
            py::gil_scoped_release unlocked;
            try {
                built->accel = std::make_unique<canopy::Accel>(arrays, std::span<const canopy::MeshInstance>{}, options_);
            } catch (const std::exception& e) {
                throw std::invalid_argument(std::string("Scene: ") + e.what());
            }
        }
        if (meshes_.size() == meshes.size()) built_ = built;  // no mesh was added while it built
        return built;
    }

    size_t meshes() const { return meshes_.size(); }

private:
    struct Mesh {
        std::vector<float> vertices;
        std::vector<uint32_t> triangles;
    };
    canopy::AccelOptions options_;
    std::vector<std::shared_ptr<const Mesh>> meshes_;
    std::shared_ptr<const BuiltScene> built_;
};

template <class T>
void fill(py::array_t<T>& a, T value) { std::fill(a.mutable_data(), a.mutable_data() + a.size(), value); }

py::dict scene_intersect(Scene& scene, const py::object& rays, const py::object& directions, const py::object& tmin,
                         const py::object& tmax, bool strict) {
    const RayArgs args(rays, directions, tmin, tmax);
    auto t = batch_output<float>(args.shape), u = batch_output<float>(args.shape), v = batch_output<float>(args.shape);
    auto normal = batch_output<float>(args.shape, {3});
    auto triangle = batch_output<int32_t>(args.shape), geometry = batch_output<int32_t>(args.shape);
    const auto built = scene.built();
    if (const canopy::Accel* accel = built->accel.get()) {
        const canopy::HitBatch hits{span_of(t), ids_of(triangle), span_of(u), span_of(v), ids_of(geometry), span_of(normal)};
        args.run([&] { accel->intersect(args.batch(strict), hits); });
        built->to_geometry(geometry);
    } else {
        args.run([&] { canopy::Accel::check_rays(args.batch(strict)); });
        fill(t, canopy::kInfinity), fill(u, 0.0f), fill(v, 0.0f), fill(normal, 0.0f), fill(triangle, -1), fill(geometry, -1);
    }
    return py::dict("t"_a = t, "triangle"_a = triangle, "geometry"_a = geometry, "u"_a = u, "v"_a = v, "normal"_a = normal);
}

// A per-ray answer of type T: query(accel, batch, out) where the scene has triangles, `miss` for every ray where not.
template <class T, class Query>
py::array_t<T> scene_per_ray(Scene& scene, const RayArgs& args, bool strict, T miss, Query&& query) {
    auto out = batch_output<T>(args.shape);
    const auto built = scene.built();
    if (const canopy::Accel* accel = built->accel.get()) {
        args.run([&] { query(*accel, args.batch(strict), out); });
    } else {
        args.run([&] { canopy::Accel::check_rays(args.batch(strict)); });
        fill(out, miss);
    }
    return out;
}

py::array_t<bool> scene_occluded(Scene& scene, const py::object& rays, const py::object& directions, const py::object& tmin,
                                 const py::object& tmax, bool strict) {
    return scene_per_ray(scene, RayArgs(rays, directions, tmin, tmax), strict, false,
                         [](const canopy::Accel& accel, const canopy::RayBatch& batch, py::array_t<bool>& out) { accel.occluded(batch, span_of(out)); });
}

py::array_t<int32_t> scene_count(Scene& scene, const py::object& rays, const py::object& directions, const py::object& tmin,
                                 const py::object& tmax, bool strict) {
    return scene_per_ray(scene, RayArgs(rays, directions, tmin, tmax), strict, int32_t(0),
                         [](const canopy::Accel& accel, const canopy::RayBatch& batch, py::array_t<int32_t>& out) { accel.count_hits(batch, ids_of(out)); });
}

template <class T, class U = T>
py::array_t<T> to_numpy(const std::vector<U>& values) {
    py::array_t<T> out(py::ssize_t(values.size()));
    if (!values.empty()) std::memcpy(out.mutable_data(), values.data(), values.size() * sizeof(T));  // no null source
    return out;
}

py::dict scene_list(Scene& scene, const py::object& rays, const py::object& directions, const py::object& tmin,
                    const py::object& tmax, bool strict) {
    const RayArgs args(rays, directions, tmin, tmax);
    canopy::HitList hits;
    const auto built = scene.built();
    if (const canopy::Accel* accel = built->accel.get()) {
        args.run([&] { accel->intersect_all(args.batch(strict), hits); });
    } else {
        args.run([&] { canopy::Accel::check_rays(args.batch(strict)); });
        hits.offsets.assign(size_t(args.count) + 1, 0);
    }
    py::array_t<int64_t> offsets = to_numpy<int64_t>(hits.offsets), ray(py::ssize_t(hits.t.size()));
    for (size_t i = 0; i + 1 < hits.offsets.size(); ++i)
        std::fill(ray.mutable_data() + hits.offsets[i], ray.mutable_data() + hits.offsets[i + 1], int64_t(i));
    py::array_t<int32_t> triangle = to_numpy<int32_t>(hits.triangle), geometry = to_numpy<int32_t>(hits.instance);
    built->to_geometry(geometry);
    return py::dict("offsets"_a = offsets, "ray"_a = ray, "t"_a = to_numpy<float>(hits.t), "triangle"_a = triangle,
                    "geometry"_a = geometry, "u"_a = to_numpy<float>(hits.u), "v"_a = to_numpy<float>(hits.v));
}

// Points of shape (..., 3) for the point queries, and their batch shape.
struct PointArgs {
    py::array_t<float, py::array::c_style> points;
    std::vector<py::ssize_t> shape;

    explicit PointArgs(const py::object& object) { std::tie(points, shape) = batch_array(object, "points", 3); }
    std::span<const float> values() const { return floats(points); }
    template <class F>
    void run(F&& f) const {
        without_gil(f, [](std::string message) { return message; });
    }
    // The errors a scene without triangles still raises (strict): a non-finite point.
    void check(bool strict) const {
        if (!strict) return;
        const float* p = points.data();
        for (py::ssize_t i = 0; i < points.size(); ++i)
            if (!std::isfinite(p[i]))
                throw py::value_error("points[" + std::to_string(i / 3) + "]: " + "xyz"[i % 3] + " is not finite");
    }
};

py::dict scene_closest_points(Scene& scene, const py::object& object, bool strict) {
    const PointArgs args(object);
    auto point = batch_output<float>(args.shape, {3}), distance = batch_output<float>(args.shape);
    auto u = batch_output<float>(args.shape), v = batch_output<float>(args.shape);
    auto triangle = batch_output<int32_t>(args.shape), geometry = batch_output<int32_t>(args.shape);
    const auto built = scene.built();
    if (const canopy::Accel* accel = built->accel.get()) {
        const canopy::PointBatch out{span_of(point), span_of(distance), ids_of(triangle), ids_of(geometry), span_of(u), span_of(v)};
        args.run([&] { accel->closest_points(args.values(), out, !strict); });
        built->to_geometry(geometry);
    } else {
        args.check(strict);
        fill(point, std::numeric_limits<float>::quiet_NaN()), fill(distance, canopy::kInfinity);
        fill(u, 0.0f), fill(v, 0.0f), fill(triangle, -1), fill(geometry, -1);
    }
    return py::dict("point"_a = point, "distance"_a = distance, "triangle"_a = triangle, "geometry"_a = geometry, "u"_a = u, "v"_a = v);
}

py::array_t<float> scene_distance(Scene& scene, const py::object& object, bool strict) {
    return scene_closest_points(scene, object, strict)["distance"].cast<py::array_t<float>>();
}

py::array_t<bool> scene_occupancy(Scene& scene, const py::object& object, bool strict) {
    const PointArgs args(object);
    auto inside = batch_output<bool>(args.shape);
    const auto built = scene.built();
    if (const canopy::Accel* accel = built->accel.get()) {
        args.run([&] { accel->contains(args.values(), span_of(inside), !strict); });
    } else {
        args.check(strict);
        fill(inside, false);
    }
    return inside;
}

py::array_t<float> scene_signed_distance(Scene& scene, const py::object& object, bool strict) {
    auto distance = scene_distance(scene, object, strict);
    const auto inside = scene_occupancy(scene, object, strict);
    float* d = distance.mutable_data();
    for (py::ssize_t i = 0; i < distance.size(); ++i)
        if (inside.data()[i]) d[i] = -d[i];
    return distance;
}

py::dict stats(const canopy::Accel& accel, bool epo) {
    const canopy::AccelStats s = [&] {
        py::gil_scoped_release unlocked;
        return accel.stats(epo);
    }();
    return py::dict("builder"_a = s.builder, "kernel"_a = s.kernel, "reason"_a = s.reason, "triangles"_a = s.triangles,
                    "build_ms"_a = s.build_ms, "sah"_a = s.sah, "epo"_a = s.epo, "layout_sah"_a = s.layout_sah,
                    "nodes"_a = s.nodes, "leaves"_a = s.leaves, "depth"_a = s.depth,
                    "references_per_triangle"_a = s.references_per_triangle, "bytes"_a = s.bytes);
}

py::tuple load_triangles(const std::string& path) {
    const canopy::TriangleMesh mesh = canopy::load_triangles(path);
    py::array_t<float> vertices({py::ssize_t(mesh.vertices.size() / 3), py::ssize_t(3)});
    py::array_t<uint32_t> triangles({py::ssize_t(mesh.triangles.size() / 3), py::ssize_t(3)});
    std::memcpy(vertices.mutable_data(), mesh.vertices.data(), mesh.vertices.size() * sizeof(float));
    std::memcpy(triangles.mutable_data(), mesh.triangles.data(), mesh.triangles.size() * sizeof(uint32_t));
    return py::make_tuple(vertices, triangles);
}

}  // namespace

PYBIND11_MODULE(_canopy, m) {
    m.doc() = "canopy: BVH builders, ray and point queries over numpy arrays";
    m.attr("__version__") = CANOPY_VERSION;

    py::class_<canopy::Accel>(m, "Accel", "A BVH over one mesh (or its instances), built once, then queried with batches of rays.")
        .def(py::init(&make_accel), "vertices"_a, "triangles"_a, py::kw_only(), "builder"_a = "binned", "kernel"_a = "auto",
             "robust"_a = true, "watertight"_a = true, "threads"_a = 0, "instances"_a = py::none(), "toplevel"_a = "flat",
             "layout"_a = "standard", "collapse"_a = "",
             "vertices: (n, 3) float32; triangles: (m, 3) uint32 or other integers; builder: a name of builders() (binned, "
             "the default, is the plain SAH build) or 'auto' (candidates timed on the path tracer's frames); kernel: "
             "'bvh2', 'bvh4', 'bvh8' or 'auto'; threads: 0 for all; instances: None, or (k, 3, 4) "
             "row-major transforms each placing the mesh (hits then name the instance); toplevel: how instances are "
             "built, 'flat', 'two-level' or 'rebraid'; layout: bvh8 nodes, 'standard' or 'compressed' (half the node "
             "bytes, the same hits; a named builder, kernel 'bvh8', toplevel 'flat'); collapse: how bvh4 and bvh8 are made, "
             "'' for the builder's own (lbvh: 'direct', straight from its Morton codes; others: 'optimal'), 'optimal', "
             "'greedy' or 'direct' (lbvh only).")
        .def("intersect", &intersect, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             py::kw_only(), "with_instance"_a = false, "strict"_a = false,
             "Closest hits of (n, 3) origins and directions in (tmin, tmax] (numbers, or one a ray; tmin >= 0): arrays t, "
             "triangle, u, v (and instance), with t inf and triangle -1 for misses. A ray with a non-finite value is a "
             "miss; strict=True raises ValueError naming it instead.")
        .def("occluded", &occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             py::kw_only(), "strict"_a = false, "Whether each ray hits anything in (tmin, tmax]: a bool array.")
        .def("stats", &stats, py::kw_only(), "epo"_a = false,
             "The tree's statistics: builder (auto's choice), kernel, build_ms, sah, nodes, bytes, ...; epo=True also "
             "computes the end-point overlap (seconds on large scenes).");

    const char* rays_doc =
        "Rays are (..., 6) rows (origin x, y, z, direction x, y, z) or separate (..., 3) origins and directions, "
        "float32 (read in place) or float64 (converted to float32 first, one pass over the batch); directions need not "
        "be unit length and t is in units of their length. Hits lie in (tmin, tmax]: tmin and tmax are numbers or "
        "arrays of the batch's shape, tmin >= 0. A ray with a non-finite value answers as a miss; strict=True raises "
        "ValueError naming it instead. Results have the batch's shape (...).";
    const char* points_doc =
        "points: (..., 3), float32 or float64 (converted). A non-finite point finds nothing (strict=True: ValueError).";
    py::class_<Scene>(m, "Scene",
                      "Several triangle meshes, each with a geometry id, and the queries Open3D's RaycastingScene and "
                      "trimesh.ray answer: closest hit, any hit, every hit along a ray, closest points, distances, signed "
                      "distances and occupancy. The BVH is built at the first query after add_mesh, with the builder, "
                      "kernel and modes given here (the same as Accel's).")
        .def(py::init([](const std::string& builder, const std::string& kernel, bool robust, bool watertight, int threads) {
                 return Scene(canopy::AccelOptions{builder, kernel, robust, watertight, "flat", threads, "standard", ""});
             }),
             py::kw_only(), "builder"_a = "binned", "kernel"_a = "auto", "robust"_a = true, "watertight"_a = true, "threads"_a = 0)
        .def("add_mesh", &Scene::add_mesh, "vertices"_a, "triangles"_a,
             "Adds a mesh of (n, 3) vertices (float32, or float64 converted) and (m, 3) integer triangles; returns its "
             "geometry id, 0, 1, ... in the order added. A mesh of no triangles takes an id and is never hit.")
        .def("intersect", &scene_intersect, "rays"_a, "directions"_a = py::none(), "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             py::kw_only(), "strict"_a = false,
             (std::string("Closest hits: a dict of arrays t (inf for a miss), triangle and geometry (-1 for a miss), u, v "
                          "(barycentric weights of the triangle's second and third vertex) and normal (..., 3), the unit "
                          "geometric normal (v1 - v0) x (v2 - v0). t is the distance on the hit triangle's plane to double "
                          "precision, rounded to float32; a surface through the origin (t = 0) is not hit. ") + rays_doc).c_str())
        .def("occluded", &scene_occluded, "rays"_a, "directions"_a = py::none(), "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             py::kw_only(), "strict"_a = false, (std::string("Whether each ray hits anything: bool (...). ") + rays_doc).c_str())
        .def("count_intersections", &scene_count, "rays"_a, "directions"_a = py::none(), "tmin"_a = 0.0f,
             "tmax"_a = canopy::kInfinity, py::kw_only(), "strict"_a = false,
             (std::string("The number of triangles each ray hits: int32 (...); a ray through a shared edge counts each "
                          "triangle it touches. ") + rays_doc).c_str())
        .def("list_intersections", &scene_list, "rays"_a, "directions"_a = py::none(), "tmin"_a = 0.0f,
             "tmax"_a = canopy::kInfinity, py::kw_only(), "strict"_a = false,
             (std::string("Every hit along each ray, in order of t: a dict of flat arrays t, triangle, geometry, u, v, ray "
                          "(the ray's index in the flattened batch) and offsets (int64, one more than the rays): ray i's "
                          "hits are entries offsets[i] to offsets[i + 1]. ") + rays_doc).c_str())
        .def("closest_points", &scene_closest_points, "points"_a, py::kw_only(), "strict"_a = false,
             (std::string("The nearest surface point of each point, by a BVH walk: a dict of point (..., 3), distance, "
                          "triangle, geometry, u, v (barycentric weights of that point). Without triangles: distance "
                          "inf, ids -1. ") + points_doc).c_str())
        .def("distance", &scene_distance, "points"_a, py::kw_only(), "strict"_a = false,
             (std::string("Unsigned distance to the surface: float32 (...). ") + points_doc).c_str())
        .def("signed_distance", &scene_signed_distance, "points"_a, py::kw_only(), "strict"_a = false,
             (std::string("Distance to the surface, negative inside it: inside by the parity of a ray's crossings, the "
                          "majority of three rays of fixed directions, meaningful for closed meshes. ") + points_doc).c_str())
        .def("occupancy", &scene_occupancy, "points"_a, py::kw_only(), "strict"_a = false,
             (std::string("Whether each point is inside the surface (as signed_distance decides): bool (...). ") + points_doc).c_str())
        .def_property_readonly("meshes", &Scene::meshes, "The number of meshes added.");

    m.def("builders", [] {
        py::dict builders;
        for (const canopy::BuilderDescription& b : canopy::registered_builders()) {
            py::dict params;
            for (const canopy::BuilderParamDescription& p : b.params)
                params[py::str(p.key)] = py::dict("default"_a = p.default_value, "help"_a = p.help);
            builders[py::str(b.name)] = py::dict("description"_a = b.description, "params"_a = params);
        }
        return builders;
    }, "The registered builders by name, each with its description and parameters (key: default and help); Accel's "
       "and Scene's builder takes a name, 'NAME:key=value,key=value', or 'auto'.");
    m.def("load_triangles", &load_triangles, "path"_a,
          "Loads an .obj, .gltf, .glb, scene.json or gen:NAME?tris=N as world-space (vertices, triangles) arrays.");
}
