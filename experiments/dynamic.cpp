#include "experiments/dynamic.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/vec4.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>

namespace canopy {
namespace {

// One instance of two_level_input(scene), in its order: scene instances, each with its mesh's objects.
struct Placement {
    const Mesh* mesh;
    const Object* object;
    glm::mat4 to_world;
    uint32_t first_triangle;  // in the flat scene
};

std::vector<Placement> placements(const Scene& scene) {
    std::vector<Placement> out;
    uint32_t offset = 0;
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        for (const Object& object : mesh.objects)
            out.push_back({&mesh, &object, instance.transform, offset + object.first_triangle});
        offset += uint32_t(mesh.triangles.size());
    }
    return out;
}

BBox world_bounds(const Placement& p, const FlatScene& flat) {
    BBox box;
    for (uint32_t t = p.first_triangle; t < p.first_triangle + p.object->triangle_count; ++t)
        box.extend(BBox::of(flat.triangles[t]));
    return box;
}

// auto: the largest placement spanning at most a quarter of the scene's diagonal, else the largest one.
size_t automatic_choice(const std::vector<Placement>& all, const FlatScene& flat) {
    const float quarter = 0.25f * glm::length(flat.bounds.extent());
    std::optional<size_t> small, largest;
    for (size_t i = 0; i < all.size(); ++i) {
        const uint32_t count = all[i].object->triangle_count;
        if (count == 0) continue;
        if (!largest || count > all[*largest].object->triangle_count) largest = i;
        const bool fits = glm::length(world_bounds(all[i], flat).extent()) <= quarter;
        if (fits && (!small || count > all[*small].object->triangle_count)) small = i;
    }
    return small ? *small : *largest;  // a loaded scene has triangles, so some placement has
}

std::optional<size_t> by_name(const std::vector<Placement>& all, const std::string& name) {
    for (size_t i = 0; i < all.size(); ++i)
        if (all[i].object->name == name) return i;
    for (size_t i = 0; i < all.size(); ++i)
        if (all[i].mesh->name == name) return i;
    return std::nullopt;
}

size_t parse_choice(const std::vector<Placement>& all, const FlatScene& flat, const std::string& spec) {
    const std::string range = "0 to " + std::to_string(all.size() - 1);
    if (spec == "auto") return automatic_choice(all, flat);
    if (!spec.empty() && std::all_of(spec.begin(), spec.end(), [](unsigned char c) { return std::isdigit(c); })) {
        if (spec.size() > 9 || std::stoul(spec) >= all.size())
            throw std::invalid_argument("--dynamic " + spec + ": no placed object of that index (the scene has " + range + ")");
        return std::stoul(spec);
    }
    if (const auto found = spec.empty() ? std::nullopt : by_name(all, spec)) return *found;
    throw std::invalid_argument("--dynamic '" + spec + "': no object or mesh of that name (give a name, an index from " +
                                range + ", or auto)");
}

// The axis of the world nearest the camera's up: the object turns about it and drives across the other two.
int vertical_axis(const Vec3& up) {
    const Vec3 a = glm::abs(up);
    return a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
}

// The carousel's pivot, beside the object's centre along one horizontal axis, as far as the object's horizontal
// bounding circle stays in the scene: the centre reaches twice the radius towards the pivot's side and the radius
// either way across. Of the four sides, the one that allows the widest circle, up to the object's own diameter:
// it moves about its place, which keeps it in view where it was in view at rest.
void place_pivot(DynamicObject& object, const BBox& bounds, const BBox& scene) {
    const int a = (object.up_axis + 1) % 3, b = (object.up_axis + 2) % 3;
    const Vec3 centre = bounds.center();
    const float reach = 0.5f * std::hypot(bounds.extent()[a], bounds.extent()[b]);
    auto room_below = [&](int k) { return centre[k] - reach - scene.lower[k]; };
    auto room_above = [&](int k) { return scene.upper[k] - centre[k] - reach; };
    object.pivot = centre;
    object.path_radius = 0.0f;
    for (const int along : {a, b}) {
        const int across = along == a ? b : a;
        const float sideways = std::min(room_below(across), room_above(across));
        for (const float side : {-1.0f, 1.0f}) {
            const float room = std::min(0.5f * (side > 0 ? room_above(along) : room_below(along)), sideways);
            const float radius = std::min(room, 2.0f * reach);
            if (!(radius > object.path_radius)) continue;
            object.path_radius = radius;
            object.pivot = centre;
            object.pivot[along] += side * radius;
        }
    }
}

}  // namespace

DynamicObject choose_dynamic_object(const Scene& scene, const FlatScene& flat, const std::string& spec) {
    const std::vector<Placement> all = placements(scene);
    const size_t chosen = parse_choice(all, flat, spec);
    const Placement& p = all[chosen];
    if (p.object->triangle_count == 0)
        throw std::invalid_argument("--dynamic " + spec + ": object '" + p.object->name + "' has no triangles to move");
    DynamicObject object;
    object.placement = uint32_t(chosen);
    object.name = p.object->name.empty() ? p.mesh->name : p.object->name;
    object.rest = p.to_world;
    object.first_triangle = p.first_triangle;
    for (uint32_t t = p.object->first_triangle; t < p.object->first_triangle + p.object->triangle_count; ++t) {
        const glm::uvec3& f = p.mesh->triangles[t];
        object.triangles.push_back({p.mesh->positions[f.x], p.mesh->positions[f.y], p.mesh->positions[f.z]});
    }
    object.up_axis = vertical_axis(scene_camera(scene, flat).up);
    place_pivot(object, world_bounds(p, flat), flat.bounds);
    return object;
}

glm::mat4 dynamic_placement(const DynamicObject& object, uint32_t frame) {
    const double turn = double(frame % kFramesPerTurn) / double(kFramesPerTurn);
    Vec3 axis(0.0f);
    axis[object.up_axis] = 1.0f;
    const glm::mat4 about_pivot = glm::translate(glm::mat4(1.0f), object.pivot) *
                                  glm::rotate(glm::mat4(1.0f), float(2.0 * std::numbers::pi * turn), axis) *
                                  glm::translate(glm::mat4(1.0f), -object.pivot);
    return about_pivot * object.rest;
}

void place_dynamic_object(const DynamicObject& object, const glm::mat4& to_world, FlatScene& flat) {
    auto world = [&](const Vec3& p) { return Vec3(to_world * glm::vec4(p, 1.0f)); };
    for (size_t i = 0; i < object.triangles.size(); ++i) {
        const Triangle& t = object.triangles[i];
        flat.triangles[object.first_triangle + i] = {world(t.v0), world(t.v1), world(t.v2)};
    }
}

PlacementMove move_dynamic_object(const DynamicObject& object, uint32_t frame, FlatScene& flat) {
    const glm::mat4 to_world = dynamic_placement(object, frame);
    place_dynamic_object(object, to_world, flat);
    return {object.placement, to_world, object.first_triangle, uint32_t(object.triangles.size())};
}

}  // namespace canopy
