// The Python module `canopy`: numpy arrays in and out of the public C++ API (include/canopy/canopy.h). Arrays of
// the API's own types and layout (float32 and uint32, C order) are read in place; others are converted once. The
// GIL is released while an accelerator builds and while a batch is traced. Bad input raises ValueError naming the
// argument: shapes and types are checked here, values (NaN, indices) by the C++ API, whose std::invalid_argument
// pybind11 turns into ValueError.
#include <canopy/canopy.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <optional>
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
    return py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a);
}

// Range checks of indices that are not uint32, before the conversion to uint32 would wrap them. Messages as the C++
// API's, which checks uint32 indices.
template <class Int>
void check_indices(const py::array& a, const std::string& name, size_t vertices) {
    const auto typed = py::array_t<Int, py::array::c_style | py::array::forcecast>::ensure(a);
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
    return py::array_t<uint32_t, py::array::c_style | py::array::forcecast>::ensure(a);
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
    return py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a);
}

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
    canopy::RayBatch batch() const { return {floats(origins), floats(directions), floats(tmin), floats(tmax)}; }
};

std::unique_ptr<canopy::Accel> make_accel(const py::object& vertices, const py::object& triangles, const std::string& builder,
                                          const std::string& kernel, bool robust, bool watertight, int threads,
                                          const py::object& instances, const std::string& toplevel, const std::string& layout,
                                          const std::string& collapse) {
    const auto v = float_array(vertices, "vertices");
    const py::array t = index_array(triangles, "triangles", size_t(v.shape(0)));
    const canopy::MeshArrays mesh{floats(v), {static_cast<const uint32_t*>(t.data()), size_t(t.size())}};
    std::vector<canopy::MeshInstance> placed;
    if (!instances.is_none()) {
        const auto transforms = float_array(instances, "instances", 3);
        placed.resize(transforms.shape(0));
        for (size_t i = 0; i < placed.size(); ++i) std::memcpy(placed[i].transform.data(), transforms.data(i), 12 * sizeof(float));
    }
    const canopy::AccelOptions options{builder, kernel, robust, watertight, toplevel, threads, layout, collapse};
    py::gil_scoped_release unlocked;
    return std::make_unique<canopy::Accel>(std::span(&mesh, 1), placed, options);
}

py::tuple intersect(const canopy::Accel& accel, const py::object& origins, const py::object& directions, const py::object& tmin,
                    const py::object& tmax, bool with_instance) {
    const Rays rays(origins, directions, tmin, tmax);
    py::array_t<float> t(rays.count), u(rays.count), v(rays.count);
    py::array_t<int32_t> triangle(rays.count), instance(with_instance ? rays.count : 0);
    // Misses are kNoHit, 0xffffffff: -1 in the int32 arrays Python gets.
    const canopy::HitBatch hits{{t.mutable_data(), size_t(rays.count)},
                                {reinterpret_cast<uint32_t*>(triangle.mutable_data()), size_t(rays.count)},
                                {u.mutable_data(), size_t(rays.count)},
                                {v.mutable_data(), size_t(rays.count)},
                                {reinterpret_cast<uint32_t*>(instance.mutable_data()), size_t(instance.size())}};
    {
        py::gil_scoped_release unlocked;
        accel.intersect(rays.batch(), hits);
    }
    return with_instance ? py::make_tuple(t, triangle, u, v, instance) : py::make_tuple(t, triangle, u, v);
}

py::array_t<bool> occluded(const canopy::Accel& accel, const py::object& origins, const py::object& directions,
                           const py::object& tmin, const py::object& tmax) {
    const Rays rays(origins, directions, tmin, tmax);
    py::array_t<bool> out(rays.count);
    const std::span<bool> view(out.mutable_data(), size_t(rays.count));
    py::gil_scoped_release unlocked;
    accel.occluded(rays.batch(), view);
    return out;
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

PYBIND11_MODULE(canopy, m) {
    m.doc() = "canopy: BVH builders and ray casting over numpy arrays";
    m.attr("__version__") = CANOPY_VERSION;

    py::class_<canopy::Accel>(m, "Accel", "A BVH over triangles, built once, then queried with batches of rays.")
        .def(py::init(&make_accel), "vertices"_a, "triangles"_a, py::kw_only(), "builder"_a = "auto", "kernel"_a = "auto",
             "robust"_a = true, "watertight"_a = true, "threads"_a = 0, "instances"_a = py::none(), "toplevel"_a = "flat",
             "layout"_a = "standard", "collapse"_a = "",
             "vertices: (n, 3) float32; triangles: (m, 3) uint32 or other integers; builder: a name of builders() or "
             "'auto'; kernel: 'bvh2', 'bvh4', 'bvh8' or 'auto'; threads: 0 for all; instances: None, or (k, 3, 4) "
             "row-major transforms each placing the mesh (hits then name the instance); toplevel: how instances are "
             "built, 'flat', 'two-level' or 'rebraid'; layout: bvh8 nodes, 'standard' or 'compressed' (half the node "
             "bytes, the same hits; a named builder, kernel 'bvh8', toplevel 'flat'); collapse: how bvh4 and bvh8 are made, "
             "'' for the builder's own (lbvh: 'direct', straight from its Morton codes; others: 'optimal'), 'optimal', "
             "'greedy' or 'direct' (lbvh only).")
        .def("intersect", &intersect, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             py::kw_only(), "with_instance"_a = false,
             "Closest hits of (n, 3) origins and directions in (tmin, tmax] (numbers, or one a ray): arrays t, triangle, "
             "u, v (and instance), with t inf and triangle -1 for misses.")
        .def("occluded", &occluded, "origins"_a, "directions"_a, "tmin"_a = 0.0f, "tmax"_a = canopy::kInfinity,
             "Whether each ray hits anything in (tmin, tmax]: a bool array.")
        .def("stats", &stats, py::kw_only(), "epo"_a = false,
             "The tree's statistics: builder (auto's choice), kernel, build_ms, sah, nodes, bytes, ...; epo=True also "
             "computes the end-point overlap (seconds on large scenes).");

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
       "builder takes a name, 'NAME:key=value,key=value', or 'auto'.");
    m.def("load_triangles", &load_triangles, "path"_a,
          "Loads an .obj, .gltf, .glb, scene.json or gen:NAME?tris=N as world-space (vertices, triangles) arrays.");
}
