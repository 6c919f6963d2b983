// Procedural scenes of any size, "gen:NAME?tris=N&seed=S", each with a camera looking into it.
//
// Deterministic from the seed: the random stream is splitmix64 and its mapping to numbers is
// canopy's own (std:: distributions differ between standard libraries). Geometry is computed in
// double and rounded to float once, so a last-bit difference of libm or of FMA contraction in a
// double almost never reaches the stored floats.
//
// Triangle counts are exact for box, city, foliage, mirror and triangles. Cylinders (open: 2 triangles per side),
// room and surface (closed) have even counts, so an odd N gives N + 1. Below a small minimum (box 118, city 12,
// foliage 14, mirror 144, room 108, surface 18, cylinders 6) the minimum is produced.
#include "scenes/loaders.h"

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <cmath>
#include <set>
#include <string_view>

namespace canopy {
namespace {

using glm::dvec3;
constexpr double pi = 3.14159265358979323846;
constexpr uint64_t max_triangles = 500'000'000;  // keeps every vertex index of every generator in uint32

struct GeneratorSpec {
    std::string text;  // the whole spec: names the scene and every error
    std::string generator;
    uint64_t triangles = 100'000;
    uint64_t seed = 1;
};

[[noreturn]] void spec_error(const std::string& spec, const std::string& problem) {
    throw InputError("scene spec '" + spec + "': " + problem);
}

uint64_t parse_integer(const std::string& spec, std::string_view key, std::string_view value) {
    uint64_t number = 0;
    const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), number);
    if (error != std::errc() || end != value.data() + value.size() || value.empty())
        spec_error(spec, "key '" + std::string(key) + "': '" + std::string(value) + "' is not a non-negative integer");
    return number;
}

void apply_query_item(GeneratorSpec& parsed, std::string_view item, std::set<std::string>& seen) {
    const size_t equals = item.find('=');
    if (equals == std::string_view::npos) spec_error(parsed.text, "query item '" + std::string(item) + "' is not key=value");
    const std::string key(item.substr(0, equals));
    const std::string_view value = item.substr(equals + 1);
    if (!seen.insert(key).second) spec_error(parsed.text, "key '" + key + "' is given twice");
    if (key == "tris") {
        parsed.triangles = parse_integer(parsed.text, key, value);
        if (parsed.triangles == 0 || parsed.triangles > max_triangles)
            spec_error(parsed.text, "key 'tris': must be in 1.." + std::to_string(max_triangles));
    } else if (key == "seed") {
        parsed.seed = parse_integer(parsed.text, key, value);
    } else {
        spec_error(parsed.text, "unknown key '" + key + "' (known: tris, seed)");
    }
}

Scene generate_box(const GeneratorSpec& spec);
Scene generate_city(const GeneratorSpec& spec);
Scene generate_cylinders(const GeneratorSpec& spec);
Scene generate_foliage(const GeneratorSpec& spec);
Scene generate_mirror(const GeneratorSpec& spec);
Scene generate_room(const GeneratorSpec& spec);
Scene generate_surface(const GeneratorSpec& spec);
Scene generate_triangles(const GeneratorSpec& spec);

struct Generator {
    std::string_view name;
    Scene (*generate)(const GeneratorSpec&);
    // Vertices per triangle at most: gen:triangles shares none; the others' grids and fans share most (a cube
    // face of n x n quads has (n + 1)^2 vertices for 2 n^2 triangles, n >= 3).
    uint64_t vertices_per_triangle;
};

constexpr Generator kGenerators[] = {
    {"box", generate_box, 1},
    {"city", generate_city, 2},
    {"cylinders", generate_cylinders, 1},
    {"foliage", generate_foliage, 2},
    {"mirror", generate_mirror, 1},
    {"room", generate_room, 1},
    {"surface", generate_surface, 1},
    {"triangles", generate_triangles, 3},
};
// Above every generator's count: box's and mirror's minimum, cylinders' and surface's rounding up to even.
constexpr uint64_t kMinimumTriangles = 144;
constexpr uint64_t kSmallMeshVertices = 1000;  // the room's walls, a cube's edges beyond the bound

const Generator* find_generator(std::string_view name) {
    for (const Generator& generator : kGenerators)
        if (generator.name == name) return &generator;
    return nullptr;
}

GeneratorSpec parse_spec(const std::string& spec) {
    GeneratorSpec parsed{spec, {}};
    std::string_view rest(spec);
    if (!rest.starts_with("gen:")) spec_error(spec, "a generator spec starts with 'gen:'");
    rest.remove_prefix(4);
    const size_t question = rest.find('?');
    parsed.generator = std::string(rest.substr(0, question));
    if (!find_generator(parsed.generator))
        spec_error(spec,
                   "unknown generator '" + parsed.generator +
                       "' (known: box, city, cylinders, foliage, mirror, room, surface, triangles)");
    if (question == std::string_view::npos) return parsed;
    std::set<std::string> seen;
    for (std::string_view query = rest.substr(question + 1);;) {
        const size_t ampersand = query.find('&');
        apply_query_item(parsed, query.substr(0, ampersand), seen);
        if (ampersand == std::string_view::npos) return parsed;
        query.remove_prefix(ampersand + 1);
    }
}

class Random {
public:
    explicit Random(uint64_t seed) : state_(seed) {}

    uint64_t next() {  // splitmix64
        uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1), every value exact
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    double log_uniform(double lo, double hi) { return lo * std::exp(std::log(hi / lo) * uniform()); }
    int integer(int lo, int hi) { return lo + int(next() % uint64_t(hi - lo + 1)); }  // inclusive
    dvec3 point_in_box(double lo, double hi) { return {uniform(lo, hi), uniform(lo, hi), uniform(lo, hi)}; }
    dvec3 direction() {  // uniform on the unit sphere
        const double z = uniform(-1.0, 1.0), phi = uniform(0.0, 2.0 * pi), r = std::sqrt(1.0 - z * z);
        return {r * std::cos(phi), r * std::sin(phi), z};
    }

private:
    uint64_t state_;
};

uint64_t integer_sqrt(uint64_t x) {
    auto root = uint64_t(std::sqrt(double(x)));
    while (root * root > x) --root;
    while ((root + 1) * (root + 1) <= x) ++root;
    return root;
}

class MeshBuilder {
public:
    uint32_t vertex(const dvec3& p) {
        mesh_.positions.emplace_back(Vec3(p));
        return uint32_t(mesh_.positions.size() - 1);
    }
    void triangle(uint32_t a, uint32_t b, uint32_t c) {
        mesh_.triangles.emplace_back(a, b, c);
        ++mesh_.objects.back().triangle_count;
    }
    void begin_object(std::string name) {
        mesh_.objects.push_back({std::move(name), uint32_t(mesh_.triangles.size()), 0});
    }
    uint32_t vertex_count() const { return uint32_t(mesh_.positions.size()); }
    BBox bounds() const {
        BBox box;
        for (const Vec3& p : mesh_.positions) box.extend(p);
        return box;
    }
    // A camera on the view from `eye_offset` (in units of the largest extent) looking at the bounds' centre.
    Camera camera_at(const dvec3& eye_offset) const {
        const BBox box = bounds();
        const Vec3 center = box.center(), extent = box.upper - box.lower;
        const float size = std::max({extent.x, extent.y, extent.z});
        return {center + Vec3(eye_offset) * size, center, {0, 1, 0}, 50.0f};
    }

    Scene into_scene(const std::string& name, const Camera& camera) && {
        Scene scene;
        scene.name = name;
        mesh_.name = name;
        scene.meshes.push_back(std::move(mesh_));
        scene.instances.push_back({0, glm::mat4(1.0f)});
        scene.camera = camera;
        return scene;
    }

private:
    Mesh mesh_;
};

// Spreads `count` units over `total` items evenly, with no randomness: each item's share is the floor or the
// ceiling of count / total, so with count <= total it picks `count` of the items.
struct EvenSelection {
    uint64_t count = 0;
    uint64_t total = 1;
    uint64_t share(uint64_t item) const { return (item + 1) * count / total - item * count / total; }
    bool picks(uint64_t item) const { return share(item) > 0; }
};

enum class GridWrap { none, columns, both };  // both: a torus

// A cols x rows grid of quads; point(i, j) maps grid coordinates to space. With wrap, the last
// column (and with GridWrap::both the last row) joins the first. Cells that `split` picks (numbered
// from first_cell) are cut into 4 triangles about their centre instead of 2: each adds exactly 2
// triangles and keeps a closed surface closed, which is how closed surfaces reach an exact even count.
template <class PointOf>
void add_grid(MeshBuilder& mesh, uint32_t cols, uint32_t rows, GridWrap wrap, const EvenSelection& split,
              uint64_t first_cell, const PointOf& point) {
    const uint32_t vertex_cols = wrap != GridWrap::none ? cols : cols + 1;
    const uint32_t vertex_rows = wrap == GridWrap::both ? rows : rows + 1;
    const uint32_t base = mesh.vertex_count();
    for (uint32_t j = 0; j < vertex_rows; ++j)
        for (uint32_t i = 0; i < vertex_cols; ++i) mesh.vertex(point(double(i), double(j)));
    const auto corner = [&](uint32_t i, uint32_t j) { return base + (j % vertex_rows) * vertex_cols + i % vertex_cols; };
    for (uint32_t j = 0; j < rows; ++j) {
        for (uint32_t i = 0; i < cols; ++i) {
            const uint32_t a = corner(i, j), b = corner(i + 1, j), c = corner(i + 1, j + 1), d = corner(i, j + 1);
            if (split.picks(first_cell + uint64_t(j) * cols + i)) {
                const uint32_t m = mesh.vertex(point(i + 0.5, j + 0.5));
                mesh.triangle(a, b, m);
                mesh.triangle(b, c, m);
                mesh.triangle(c, d, m);
                mesh.triangle(d, a, m);
            } else {
                mesh.triangle(a, b, c);
                mesh.triangle(a, c, d);
            }
        }
    }
}

// The cube [-1, 1]^3 with n x n quads per face, mapped through place(). Points come from integer
// lattice coordinates, so faces meeting at an edge compute bit-identical points: no cracks.
template <class Place>
void add_cube_surface(MeshBuilder& mesh, uint32_t n, uint64_t split_cells, const Place& place) {
    const uint64_t cells_per_face = uint64_t(n) * n;
    const EvenSelection split{split_cells, 6 * cells_per_face};
    for (int face = 0; face < 6; ++face) {
        const int axis = face / 2;
        const bool positive = face % 2 == 1;
        // Swapping the free axes on the negative faces keeps every face wound outwards.
        const int u_axis = positive ? (axis + 1) % 3 : (axis + 2) % 3;
        const int v_axis = positive ? (axis + 2) % 3 : (axis + 1) % 3;
        add_grid(mesh, n, n, GridWrap::none, split, uint64_t(face) * cells_per_face, [&](double i, double j) {
            dvec3 lattice;
            lattice[axis] = positive ? n : 0;
            lattice[u_axis] = i;
            lattice[v_axis] = j;
            return place(-1.0 + 2.0 * lattice / double(n));
        });
    }
}

// A cube surface of exactly `budget` triangles (even, at least 108 so that the split cells fit).
template <class Place>
void add_cube_with_budget(MeshBuilder& mesh, uint64_t budget, const Place& place) {
    const auto n = uint32_t(integer_sqrt(budget / 12));
    add_cube_surface(mesh, n, (budget - 12 * uint64_t(n) * n) / 2, place);
}

// ---- gen:box: a Cornell-like room, open at +z where the camera is, holding spheres and boxes.

constexpr uint64_t min_box_shape_triangles = 108;  // a 3 x 3 cube: room for every split cell
constexpr uint64_t room_triangles = 10;

// A convex polygon as a fan from its first corner: corners - 2 triangles.
void add_polygon(MeshBuilder& mesh, const std::string& name, std::initializer_list<dvec3> corners) {
    mesh.begin_object(name);
    const uint32_t first = mesh.vertex(*corners.begin());
    for (auto corner = corners.begin() + 1; corner != corners.end(); ++corner) mesh.vertex(*corner);
    for (uint32_t k = 1; k + 1 < corners.size(); ++k) mesh.triangle(first, first + k, first + k + 1);
}

// Room [-1, 1] x [0, 2] x [-1, 1], open at +z. An odd budget gives the back wall a fifth corner
// (the middle of its floor edge) and so a third triangle.
void add_room(MeshBuilder& mesh, bool odd) {
    add_polygon(mesh, "floor", {{-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, {-1, 0, -1}});
    add_polygon(mesh, "ceiling", {{-1, 2, 1}, {-1, 2, -1}, {1, 2, -1}, {1, 2, 1}});
    add_polygon(mesh, "left_wall", {{-1, 0, 1}, {-1, 0, -1}, {-1, 2, -1}, {-1, 2, 1}});
    add_polygon(mesh, "right_wall", {{1, 0, -1}, {1, 0, 1}, {1, 2, 1}, {1, 2, -1}});
    if (odd) add_polygon(mesh, "back_wall", {{0, 0, -1}, {1, 0, -1}, {1, 2, -1}, {-1, 2, -1}, {-1, 0, -1}});
    else add_polygon(mesh, "back_wall", {{-1, 0, -1}, {1, 0, -1}, {1, 2, -1}, {-1, 2, -1}});
}

struct FloorCell {
    dvec3 center;  // on the floor
    double size;
};

void add_sphere(MeshBuilder& mesh, Random& random, const FloorCell& cell, uint64_t budget) {
    const double radius = cell.size * random.uniform(0.25, 0.42);
    const dvec3 center = cell.center + dvec3(0, radius, 0);
    add_cube_with_budget(mesh, budget, [&](const dvec3& p) { return center + radius * glm::normalize(p); });
}

void add_box(MeshBuilder& mesh, Random& random, const FloorCell& cell, uint64_t budget) {
    const dvec3 half(cell.size * random.uniform(0.18, 0.32), random.uniform(0.1, 0.6), cell.size * random.uniform(0.18, 0.32));
    const double angle = random.uniform(0.0, 0.5 * pi), c = std::cos(angle), s = std::sin(angle);
    const dvec3 center = cell.center + dvec3(0, half.y, 0);
    add_cube_with_budget(mesh, budget, [&](const dvec3& p) {
        const dvec3 q = p * half;
        return center + dvec3(c * q.x + s * q.z, q.y, -s * q.x + c * q.z);
    });
}

Scene generate_box(const GeneratorSpec& spec) {
    const uint64_t wanted = std::max(spec.triangles, room_triangles + min_box_shape_triangles);
    const bool odd = (wanted - room_triangles) % 2 == 1;
    const uint64_t shape_budget = wanted - room_triangles - (odd ? 1 : 0);
    // About sqrt(budget / 600) shapes: a handful for small scenes, up to 64 for millions.
    const uint64_t shapes = std::clamp<uint64_t>(uint64_t(std::lround(std::sqrt(double(shape_budget) / 600.0))), 1,
                                                 std::min<uint64_t>(64, shape_budget / min_box_shape_triangles));
    const auto grid = uint32_t(std::ceil(std::sqrt(double(shapes))));
    const double cell_size = 1.8 / grid;

    Random random(spec.seed);
    MeshBuilder mesh;
    add_room(mesh, odd);
    const uint64_t pairs = shape_budget / 2;
    for (uint64_t k = 0; k < shapes; ++k) {
        const uint64_t budget = 2 * (pairs / shapes + (k < pairs % shapes ? 1 : 0));
        const double jitter = 0.1 * cell_size;
        const FloorCell cell{{-0.9 + (double(k % grid) + 0.5) * cell_size + random.uniform(-jitter, jitter), 0.0,
                              -0.9 + (double(k / grid) + 0.5) * cell_size + random.uniform(-jitter, jitter)},
                             cell_size};
        const bool sphere = random.uniform() < 0.5;
        mesh.begin_object((sphere ? "sphere_" : "box_") + std::to_string(k));
        if (sphere) add_sphere(mesh, random, cell, budget);
        else add_box(mesh, random, cell, budget);
    }
    return std::move(mesh).into_scene(spec.text, {{0, 1.1, 3.0}, {0, 0.8, 0}, {0, 1, 0}, 40.0f});
}

// ---- gen:cylinders: a Power-Plant-like tangle of long, thin, open cylinders in [-1, 1]^3.

// Two unit vectors perpendicular to the unit vector `axis` and to each other.
std::pair<dvec3, dvec3> perpendiculars(const dvec3& axis) {
    const dvec3 helper = std::abs(axis.x) < 0.9 ? dvec3(1, 0, 0) : dvec3(0, 1, 0);
    const dvec3 u = glm::normalize(glm::cross(axis, helper));
    return {u, glm::cross(axis, u)};
}

// An open tube of `sides` quads (2 sides triangles) from `from` to `to`.
void add_tube(MeshBuilder& mesh, const dvec3& from, const dvec3& to, double radius, uint32_t sides) {
    const auto [u, w] = perpendiculars(glm::normalize(to - from));
    const uint32_t base = mesh.vertex_count();
    for (uint32_t k = 0; k < sides; ++k) {
        const double angle = 2.0 * pi * k / sides;
        const dvec3 offset = radius * (std::cos(angle) * u + std::sin(angle) * w);
        mesh.vertex(from + offset);
        mesh.vertex(to + offset);
    }
    for (uint32_t k = 0; k < sides; ++k) {
        const uint32_t bottom = base + 2 * k, top = bottom + 1;
        const uint32_t next_bottom = base + 2 * ((k + 1) % sides), next_top = next_bottom + 1;
        mesh.triangle(bottom, next_bottom, next_top);
        mesh.triangle(bottom, next_top, top);
    }
}

void add_cylinder(MeshBuilder& mesh, Random& random, const dvec3& center, double spacing, uint32_t sides) {
    const double length = std::min(random.uniform(3.0, 10.0) * spacing, 2.0);
    const double radius = length * random.uniform(1.0 / 60.0, 1.0 / 25.0);
    const dvec3 axis = random.direction();
    add_tube(mesh, center - 0.5 * length * axis, center + 0.5 * length * axis, radius, sides);
}

Scene generate_cylinders(const GeneratorSpec& spec) {
    const uint64_t total_sides = std::max<uint64_t>((spec.triangles + 1) / 2, 3);
    const uint64_t cylinders = std::max<uint64_t>(total_sides / 6, 1);  // 6 or 7 sides each
    // Objects are the cylinders whose centres share a cell of a grid x grid x grid partition of
    // the cube, about 256 cylinders each; their boxes overlap, as the Power Plant's parts do.
    const auto grid = uint32_t(std::clamp<long>(std::lround(std::cbrt(double(cylinders) / 256.0)), 1, 16));
    const uint64_t cells = uint64_t(grid) * grid * grid;
    const double spacing = 2.0 / std::cbrt(double(cylinders)), cell_size = 2.0 / grid;

    Random random(spec.seed);
    MeshBuilder mesh;
    uint64_t index = 0;
    for (uint64_t cell = 0; cell < cells; ++cell) {
        mesh.begin_object("cylinders_" + std::to_string(cell));
        const dvec3 corner = dvec3(double(cell % grid), double(cell / grid % grid), double(cell / grid / grid)) * cell_size - 1.0;
        const uint64_t in_cell = cylinders / cells + (cell < cylinders % cells ? 1 : 0);
        for (uint64_t k = 0; k < in_cell; ++k, ++index) {
            const auto sides = uint32_t(total_sides / cylinders + (index < total_sides % cylinders ? 1 : 0));
            add_cylinder(mesh, random, corner + random.point_in_box(0.0, cell_size), spacing, sides);
        }
    }
    return std::move(mesh).into_scene(spec.text, {{0, 0.9, 2.8}, {0, 0, 0}, {0, 1, 0}, 50.0f});
}

// ---- gen:foliage: a tree seen from outside, as a scanned plant is: a trunk and branches (thin tubes of 6 sides)
// carrying clusters of thin leaves, each a diamond of two triangles at a random orientation about a point of its
// branch's outer part. The leaves are slivers whose boxes are mostly empty at every orientation, packed densely in
// the crown: splits pay there, yet a leaf's box is small against the scene's.

constexpr uint32_t kBranchSides = 6;
constexpr uint64_t kTrianglesPerBranch = 400;  // of the budget: a branch, the rest its leaves
constexpr uint64_t kBranchesPerObject = 8;     // leaves of this many consecutive branches form an object

// A leaf of `length` centred at `center`: a diamond of two triangles, or its first half alone.
void add_leaf(MeshBuilder& mesh, Random& random, const dvec3& center, double length, bool whole) {
    const dvec3 along = random.direction();
    const auto [u, w] = perpendiculars(along);
    const double turn = random.uniform(0.0, 2.0 * pi), width = length * random.uniform(0.15, 0.3);
    const dvec3 across = 0.5 * width * (std::cos(turn) * u + std::sin(turn) * w);
    const uint32_t base = mesh.vertex(center - 0.5 * length * along), tip = mesh.vertex(center + 0.5 * length * along);
    mesh.triangle(base, mesh.vertex(center + across), tip);
    if (whole) mesh.triangle(base, tip, mesh.vertex(center - across));
}

Scene generate_foliage(const GeneratorSpec& spec) {
    const uint64_t total = std::max<uint64_t>(spec.triangles, 2 * kBranchSides + 2);
    const uint64_t branches = std::max<uint64_t>(total / kTrianglesPerBranch, 1);
    const uint64_t leaf_triangles = total - 2 * kBranchSides * branches;
    const uint64_t leaves = (leaf_triangles + 1) / 2;  // an odd count makes the last leaf one triangle
    const double leaf_length = std::min(1.2 / std::cbrt(double(leaves)), 0.2);

    Random random(spec.seed);
    MeshBuilder mesh;
    mesh.begin_object("branches");
    std::vector<std::pair<dvec3, dvec3>> limbs{{dvec3(0, -1, 0), dvec3(0, 0, 0)}};  // the trunk first
    add_tube(mesh, limbs[0].first, limbs[0].second, 0.04, kBranchSides);
    while (limbs.size() < branches) {
        const dvec3 base(0.0, random.uniform(-0.6, 0.0), 0.0);
        dvec3 direction = random.direction();
        direction.y = 0.2 + 0.8 * std::abs(direction.y);  // upwards and outwards
        const dvec3 tip = base + random.uniform(0.4, 0.9) * glm::normalize(direction);
        add_tube(mesh, base, tip, random.uniform(0.008, 0.015), kBranchSides);
        limbs.emplace_back(base, tip);
    }
    const EvenSelection per_branch{leaves, branches};
    uint64_t leaf = 0;
    for (uint64_t b = 0; b < branches; ++b) {
        if (b % kBranchesPerObject == 0) mesh.begin_object("leaves_" + std::to_string(b / kBranchesPerObject));
        const auto& [base, tip] = limbs[b];
        for (uint64_t k = 0; k < per_branch.share(b); ++k, ++leaf) {
            const dvec3 center = base + random.uniform(0.3, 1.0) * (tip - base) + random.uniform(0.0, 0.15) * random.direction();
            add_leaf(mesh, random, center, leaf_length * random.uniform(0.7, 1.3), leaf + 1 < leaves || leaf_triangles % 2 == 0);
        }
    }
    const Camera camera = mesh.camera_at({0.0, 0.2, 1.1});
    return std::move(mesh).into_scene(spec.text, camera);
}

// ---- gen:city: a grid of blocks between streets, each block holding axis-aligned buildings of widely varied
// footprints and heights (both log-uniform: sheds to towers 25 times as tall), seen from street level at the
// city's edge, down the middle street. Thin street markings just above the ground take the budget's remainder.

constexpr uint64_t kBuildingTriangles = 10;  // a box open at the ground
constexpr uint64_t kBuildingsPerBlock = 16;

// The box [lower, upper] without its bottom face: 8 corners, 10 triangles facing outwards.
void add_building(MeshBuilder& mesh, const dvec3& lower, const dvec3& upper) {
    const uint32_t base = mesh.vertex_count();
    for (int k = 0; k < 8; ++k)  // corner k: x from bit 0, y from bit 1, z from bit 2
        mesh.vertex({k & 1 ? upper.x : lower.x, k & 2 ? upper.y : lower.y, k & 4 ? upper.z : lower.z});
    const uint32_t faces[5][4] = {{2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}, {0, 4, 6, 2}, {1, 3, 7, 5}};  // top, -z, +z, -x, +x
    for (const auto& f : faces) {
        mesh.triangle(base + f[0], base + f[1], base + f[2]);
        mesh.triangle(base + f[0], base + f[2], base + f[3]);
    }
}

// A street marking: a thin strip along a street's centre line, just above the ground, or its first half alone.
void add_marking(MeshBuilder& mesh, Random& random, uint32_t blocks_across, double pitch, bool whole) {
    const double line = -1.0 + pitch * random.integer(0, int(blocks_across)), along = random.uniform(-1.0, 1.0);
    const double half_length = 0.15 * pitch, half_width = 0.01 * pitch, y = 0.001;
    const bool x_street = random.integer(0, 1) == 1;  // runs along z at x = line, else along x at z = line
    const auto at = [&](double a, double b) { return x_street ? dvec3(line + b, y, along + a) : dvec3(along + a, y, line + b); };
    const uint32_t first = mesh.vertex(at(-half_length, -half_width));
    mesh.vertex(at(-half_length, half_width));
    mesh.vertex(at(half_length, half_width));
    mesh.triangle(first, first + 1, first + 2);
    if (whole) mesh.triangle(first, first + 2, mesh.vertex(at(half_length, -half_width)));
}

Scene generate_city(const GeneratorSpec& spec) {
    const uint64_t total = std::max<uint64_t>(spec.triangles, 2 + kBuildingTriangles);
    const uint64_t buildings = std::max<uint64_t>((total - 2) * 95 / 100 / kBuildingTriangles, 1);
    const uint64_t marking_triangles = total - 2 - kBuildingTriangles * buildings;
    // An even number of blocks across, so that a street runs down the middle to the camera.
    const auto blocks_across = uint32_t(std::max<long>(2 * std::lround(0.5 * std::sqrt(double(buildings) / kBuildingsPerBlock)), 2));
    const double pitch = 2.0 / blocks_across, street = 0.2 * pitch, lot = pitch - street;

    Random random(spec.seed);
    MeshBuilder mesh;
    const double edge = 1.0 + street;
    add_polygon(mesh, "ground", {{-edge, 0, -edge}, {-edge, 0, edge}, {edge, 0, edge}, {edge, 0, -edge}});
    const uint64_t blocks = uint64_t(blocks_across) * blocks_across;
    const EvenSelection per_block{buildings, blocks};
    for (uint64_t block = 0; block < blocks; ++block) {
        mesh.begin_object("block_" + std::to_string(block));
        const dvec3 corner(-1.0 + pitch * double(block % blocks_across) + 0.5 * street, 0.0,
                           -1.0 + pitch * double(block / blocks_across) + 0.5 * street);
        for (uint64_t k = 0; k < per_block.share(block); ++k) {
            const double width = random.log_uniform(0.06, 0.45) * lot, depth = random.log_uniform(0.06, 0.45) * lot;
            const dvec3 lower = corner + dvec3(random.uniform(0.0, lot - width), 0.0, random.uniform(0.0, lot - depth));
            add_building(mesh, lower, lower + dvec3(width, random.log_uniform(0.02, 0.5), depth));
        }
    }
    if (marking_triangles) mesh.begin_object("markings");
    for (uint64_t t = 0; t < marking_triangles; t += 2)
        add_marking(mesh, random, blocks_across, pitch, t + 1 < marking_triangles);
    const Camera street_level{{0.0f, 0.015f, float(1.0 + 0.5 * street)}, mesh.bounds().center(), {0, 1, 0}, 60.0f};
    return std::move(mesh).into_scene(spec.text, street_level);
}

// ---- gen:mirror: a headlamp-like faceted parabolic reflector, tessellated as a CAD tessellator does it at a
// chordal tolerance: few rings along the dish's profile and many sectors around it, so its triangles are long
// radial slivers at every orientation about the axis, their boxes mostly empty (Ernst & Greiner 2007's "Mirror").

constexpr double mirror_focal_length = 0.3;  // the dish z = r^2 / (4 f), rim radius 1, as deep as a headlamp's
constexpr double mirror_hole = 0.2;          // the bulb's hole: no fan of needles about the axis
constexpr double mirror_flange = 1.15;       // the flat rim's outer radius
constexpr double mirror_depth = 1.0 / (4.0 * mirror_focal_length);  // at the rim
// The facet counts divide it, so facet borders fall on sector lines.
constexpr uint64_t mirror_sector_step = 24;
constexpr uint64_t min_mirror_triangles = 6 * mirror_sector_step;  // two rings of dish, so the facets show, and the rim
constexpr int mirror_facet_counts[] = {6, 8, 12};

struct MirrorTessellation {
    uint32_t rings, sectors;  // of the dish; the rim is one more ring
    uint64_t rim_extra;       // triangles beyond 2 per rim cell, fewer than 2 per cell
};

// Sectors grow as N^0.2 and rings as N^0.8. A coarse tessellation is set by the angular tolerance, which the curved
// hoop needs and the flatter profile barely does; a finer one more by the maximum edge length, which cuts the long
// radial edges. The median sliver (longest edge over height) is 46:1 at N = 85651 (16 rings, 2424 sectors) and
// 19:1 at N = 334080 (51 rings, 3192 sectors): binned SAH's cost falls where the splitting builders' barely does.
MirrorTessellation mirror_tessellation(uint64_t triangles) {
    const uint64_t wanted = std::max(triangles, min_mirror_triangles);
    const auto steps = uint64_t(std::llround(250.0 * std::pow(double(wanted), 0.2) / mirror_sector_step));
    const uint64_t sectors = mirror_sector_step * std::clamp<uint64_t>(steps, 1, wanted / min_mirror_triangles);
    const uint64_t rings = wanted / (2 * sectors) - 1;  // at least 2: sectors <= wanted / 6
    return {uint32_t(rings), uint32_t(sectors), wanted - 2 * sectors * (rings + 1)};
}

// Facets are pillows on the paraboloid, each bulging by its own amplitude; the bulge vanishes on facet borders,
// at the hole and at the rim, so neighbouring facets meet in a crease and the dish stays one surface.
struct MirrorDish {
    std::vector<double> bulges;  // per facet, a fraction of the rim's depth
    uint32_t rings, sectors;

    dvec3 point(double sector, double ring) const {
        const double per_facet = double(sectors) / double(bulges.size());
        const double facet = std::floor(sector / per_facet), across = sector / per_facet - facet;
        const double along = ring / rings, r = mirror_hole + (1.0 - mirror_hole) * along;
        const double bulge = bulges[size_t(facet)] * mirror_depth * std::sin(pi * across) * std::sin(pi * along);
        return at_angle(sector, r, r * r / (4.0 * mirror_focal_length) + bulge);
    }
    // Clockwise seen from the front, which winds the triangles to face the camera.
    dvec3 at_angle(double sector, double r, double z) const {
        const double angle = -2.0 * pi * sector / sectors;
        return {r * std::cos(angle), r * std::sin(angle), z};
    }
};

// The flat rim from the dish's last ring out to the flange. `extra` triangles are spread over its cells: a cell
// taking k has k more points on its outer edge, a boundary, so the mesh stays crack-free.
void add_mirror_rim(MeshBuilder& mesh, const MirrorDish& dish, uint32_t first_inner, uint64_t extra) {
    const uint32_t first_outer = mesh.vertex_count();
    for (uint32_t i = 0; i < dish.sectors; ++i) mesh.vertex(dish.at_angle(i, mirror_flange, mirror_depth));
    const EvenSelection extras{extra, dish.sectors};
    for (uint32_t i = 0; i < dish.sectors; ++i) {
        const uint32_t next = (i + 1) % dish.sectors, a = first_inner + i, b = first_inner + next;
        uint32_t previous = first_outer + next;
        mesh.triangle(a, b, previous);
        const auto k = uint32_t(extras.share(i));
        for (uint32_t m = k; m >= 1; --m) {  // from the outer edge's far end back towards a's side
            const uint32_t point = mesh.vertex(dish.at_angle(i + double(m) / (k + 1), mirror_flange, mirror_depth));
            mesh.triangle(a, previous, point);
            previous = point;
        }
        mesh.triangle(a, previous, first_outer + i);
    }
}

Scene generate_mirror(const GeneratorSpec& spec) {
    const MirrorTessellation tessellation = mirror_tessellation(spec.triangles);
    Random random(spec.seed);
    MirrorDish dish{{}, tessellation.rings, tessellation.sectors};
    const int facets = mirror_facet_counts[random.integer(0, 2)];
    for (int k = 0; k < facets; ++k)  // some bulge out, some in
        dish.bulges.push_back(random.uniform(0.02, 0.06) * (random.uniform() < 0.5 ? -1.0 : 1.0));

    MeshBuilder mesh;
    mesh.begin_object("mirror");
    add_grid(mesh, dish.sectors, dish.rings, GridWrap::columns, EvenSelection{}, 0,
             [&](double i, double j) { return dish.point(i, j); });
    mesh.begin_object("rim");
    add_mirror_rim(mesh, dish, dish.rings * dish.sectors, tessellation.rim_extra);  // the grid's last ring
    // In front of the dish, a little off its axis, the rim about filling the frame's height.
    return std::move(mesh).into_scene(spec.text, {{0.3, 0.4, 3.2}, {0, 0, 0.35}, {0, 1, 0}, 42.0f});
}

// ---- gen:surface: a Dragon-like bumpy torus from a regular grid: compact triangles of similar size.

constexpr double ring_radius = 1.0, tube_radius = 0.35;

struct Bump {
    int ring_frequency, tube_frequency;  // integers, so the bumps wrap around seamlessly
    double ring_phase, tube_phase, amplitude;
};

Scene generate_surface(const GeneratorSpec& spec) {
    const uint64_t cells = std::max<uint64_t>((spec.triangles + 1) / 2, 9);
    // Cells about square: rows around the tube and columns around the ring in the radii's ratio.
    const auto rows = uint32_t(std::max<long>(std::lround(std::sqrt(double(cells) * tube_radius / ring_radius)), 3));
    const auto cols = uint32_t(cells / rows);

    Random random(spec.seed);
    std::vector<Bump> bumps;
    for (int k = 0; k < 4; ++k)  // amplitudes sum below 0.5: the tube never pinches shut
        bumps.push_back({random.integer(2, 12), random.integer(1, 4), random.uniform(0, 2 * pi),
                         random.uniform(0, 2 * pi), random.uniform(0.08, 0.12)});
    const auto point = [&](double i, double j) {
        const double ring = 2.0 * pi * i / cols, tube = 2.0 * pi * j / rows;
        double bump = 0.0;
        for (const Bump& b : bumps)
            bump += b.amplitude * std::sin(b.ring_frequency * ring + b.ring_phase) * std::sin(b.tube_frequency * tube + b.tube_phase);
        const double r = tube_radius * (1.0 + bump), spoke = ring_radius + r * std::cos(tube);
        return dvec3(spoke * std::cos(ring), r * std::sin(tube), spoke * std::sin(ring));
    };
    MeshBuilder mesh;
    mesh.begin_object("surface");
    const uint64_t base_cells = uint64_t(cols) * rows;
    add_grid(mesh, cols, rows, GridWrap::both, EvenSelection{cells - base_cells, base_cells}, 0, point);
    return std::move(mesh).into_scene(spec.text, {{0, 1.7, 2.2}, {0, 0, 0}, {0, 1, 0}, 50.0f});
}

// ---- gen:room: a closed room as a scanner captures it, seen from inside: one closed surface of compact triangles of
// similar size (as gen:surface's), its walls, floor and ceiling bulging inwards where furniture and fittings stood,
// and the scanner's noise on every vertex. A cube of n x n quads a face, each point moved towards the centre.

struct Bulge {
    dvec3 center;  // on the cube's surface
    double radius, depth;
};

// Scanner noise, a small fraction of the cube's half size either way: a function of the point alone, so that faces
// meeting at an edge move their shared points alike and the surface stays closed.
double scan_noise(const dvec3& p) {
    uint64_t h = 0x9E3779B97F4A7C15ull;
    for (int axis = 0; axis < 3; ++axis) {
        uint64_t bits;
        std::memcpy(&bits, &p[axis], sizeof bits);
        h = (h ^ bits) * 0xBF58476D1CE4E5B9ull;
        h ^= h >> 29;
    }
    return 0.004 * (double(h >> 11) * 0x1.0p-53 * 2.0 - 1.0);
}

Scene generate_room(const GeneratorSpec& spec) {
    Random random(spec.seed);
    std::vector<Bulge> bulges;
    for (int k = 0; k < 16; ++k) {
        dvec3 center = random.point_in_box(-1.0, 1.0);
        center[random.integer(0, 2)] = random.integer(0, 1) ? 1.0 : -1.0;
        bulges.push_back({center, random.uniform(0.1, 0.4), random.uniform(0.05, 0.25)});
    }
    const dvec3 size(2.5, 1.3, 2.0);  // a room's proportions: wider than deep, lower than both
    MeshBuilder mesh;
    mesh.begin_object("room");
    add_cube_with_budget(mesh, std::max<uint64_t>(spec.triangles + (spec.triangles & 1), 108), [&](const dvec3& p) {
        double inwards = 0.0;
        for (const Bulge& b : bulges) {
            const dvec3 d = (p - b.center) / b.radius;
            inwards += b.depth * std::exp(-glm::dot(d, d));
        }
        return p * size * std::max(0.3, 1.0 - inwards + scan_noise(p));  // never through the centre
    });
    return std::move(mesh).into_scene(spec.text, {{0.4, -0.1, 1.3}, {-0.8, -0.5, -2.0}, {0, 1, 0}, 60.0f});
}

// ---- gen:triangles: large random triangles overlapping in [-1, 1]^3 (adversarial for any BVH).

Scene generate_triangles(const GeneratorSpec& spec) {
    // Each triangle spans about 8 mean spacings, so some 60 triangle boxes overlap any point.
    const double size = std::min(16.0 / std::cbrt(double(spec.triangles)), 2.0), half = 0.5 * size;
    Random random(spec.seed);
    MeshBuilder mesh;
    mesh.begin_object("triangles");
    for (uint64_t t = 0; t < spec.triangles; ++t) {
        const dvec3 center = random.point_in_box(-1.0 + half, 1.0 - half);
        const uint32_t a = mesh.vertex(center + random.point_in_box(-half, half));
        const uint32_t b = mesh.vertex(center + random.point_in_box(-half, half));
        const uint32_t c = mesh.vertex(center + random.point_in_box(-half, half));
        mesh.triangle(a, b, c);
    }
    return std::move(mesh).into_scene(spec.text, {{0, 0.8, 2.4}, {0, 0, 0}, {0, 1, 0}, 50.0f});
}

}  // namespace

Scene generate_scene(const std::string& spec) {
    const GeneratorSpec parsed = parse_spec(spec);
    return find_generator(parsed.generator)->generate(parsed);
}

SceneSize generated_scene_size(const std::string& spec) {
    const GeneratorSpec parsed = parse_spec(spec);
    const uint64_t triangles = std::max(parsed.triangles + 1, kMinimumTriangles);
    const uint64_t vertices = triangles * find_generator(parsed.generator)->vertices_per_triangle + kSmallMeshVertices;
    return {vertices, triangles, triangles, 1};
}

Scene default_scene() {
    Scene scene = generate_scene("gen:box?tris=30000&seed=1");
    scene.name = "default";
    return scene;
}

}  // namespace canopy
