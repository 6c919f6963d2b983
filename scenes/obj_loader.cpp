// OBJ loading. tinyobjloader parses faces and the .mtl; before it runs, a scan of the text
// records the o/g lines (the objects) and rejects what tinyobjloader would silently accept (a
// "nan" or "abc" coordinate becomes 0, an out-of-range face index is dropped with a warning),
// so every error names its line.
#include "scenes/loaders.h"

#include <tiny_obj_loader.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <set>
#include <sstream>
#include <string_view>

namespace canopy {
namespace {

namespace fs = std::filesystem;

std::string read_text_file(const std::string& path) {
    require_regular_file(path);
    std::ifstream in(path, std::ios::binary);
    std::error_code error;
    std::string text(fs::file_size(path, error), '\0');
    if (!in || error || !in.read(text.data(), std::streamsize(text.size())))
        throw InputError(path + ": cannot be read");
    return text;
}

// Next whitespace-separated token of `rest`; empty at the end of the line or at a '#' comment.
std::string_view next_token(std::string_view& rest) {
    const size_t begin = rest.find_first_not_of(" \t");
    if (begin == std::string_view::npos || rest[begin] == '#') {
        rest = {};
        return {};
    }
    const size_t end = std::min(rest.find_first_of(" \t", begin), rest.size());
    const std::string_view token = rest.substr(begin, end - begin);
    rest.remove_prefix(end);
    return token;
}

template <class Number>
bool parse_whole(std::string_view text, Number& value) {
    if (text.size() > 1 && text[0] == '+' && text[1] != '-') text.remove_prefix(1);  // from_chars rejects '+'
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    return error == std::errc() && end == text.data() + text.size();
}

// An `o` or `g` line: the start of an object, before the file's face number first_face.
struct GroupStart {
    std::string name;
    size_t first_face = 0;
};

// Validates the 'v' and 'f' lines that canopy uses, counting vertices and faces, and records
// every 'o'/'g' line (tinyobjloader drops the groups that have no faces).
class ObjScan {
public:
    explicit ObjScan(std::string path) : path_(std::move(path)) {}

    void run(std::string_view text) {
        // Lines end in "\n" or "\r\n"; a file with no "\n" at all may use old Mac "\r" endings.
        const char end_of_line = text.find('\n') == std::string_view::npos ? '\r' : '\n';
        while (!text.empty()) {
            ++line_;
            const size_t end = std::min(text.find(end_of_line), text.size());
            std::string_view line = text.substr(0, end);
            if (line.ends_with('\r')) line.remove_suffix(1);
            scan_line(line);
            text.remove_prefix(std::min(text.size(), end + 1));
        }
        if (largest_index_ > int64_t(vertex_count_))
            fail(largest_index_line_, "face index " + std::to_string(largest_index_) +
                                          " is out of range: the file has " +
                                          std::to_string(vertex_count_) + " vertices");
        if (face_count_ == 0) throw InputError(path_ + ": has no faces ('f' lines), so no triangles");
    }

    size_t vertex_count() const { return vertex_count_; }
    size_t face_count() const { return face_count_; }
    const std::vector<GroupStart>& groups() const { return groups_; }

private:
    [[noreturn]] void fail(size_t line, const std::string& problem) const {
        throw InputError(path_ + ":" + std::to_string(line) + ": " + problem);
    }

    void scan_line(std::string_view line) {
        const std::string_view keyword = next_token(line);
        if (keyword == "v") scan_vertex(line);
        if (keyword == "f") scan_face(line);
        if (keyword == "o" || keyword == "g") scan_group(line);
    }

    // The name is the rest of the line, as written ("g a b" names one object "a b").
    void scan_group(std::string_view rest) {
        std::string name;
        for (std::string_view token = next_token(rest); !token.empty(); token = next_token(rest)) {
            if (!name.empty()) name += ' ';
            name += token;
        }
        groups_.push_back({std::move(name), face_count_});
    }

    void scan_vertex(std::string_view rest) {
        int coordinates = 0;
        for (std::string_view token = next_token(rest); !token.empty(); token = next_token(rest)) {
            float value = 0;
            if (!parse_whole(token, value))
                fail(line_, "vertex coordinate '" + std::string(token) + "' is not a number in float range");
            if (!std::isfinite(value))
                fail(line_, "vertex coordinate '" + std::string(token) + "' is not finite");
            ++coordinates;
        }
        if (coordinates < 3)
            fail(line_, "a vertex needs 3 coordinates, this one has " + std::to_string(coordinates));
        ++vertex_count_;
    }

    void scan_face(std::string_view rest) {
        int corners = 0;
        for (std::string_view token = next_token(rest); !token.empty(); token = next_token(rest)) {
            check_face_index(token);
            ++corners;
        }
        if (corners < 3) fail(line_, "a face needs at least 3 vertices, this one has " + std::to_string(corners));
        ++face_count_;
    }

    // Only the position index: canopy ignores texture and normal indices.
    void check_face_index(std::string_view corner) {
        int64_t index = 0;
        if (!parse_whole(corner.substr(0, corner.find('/')), index))
            fail(line_, "face vertex '" + std::string(corner) + "' is not an index");
        if (index == 0) fail(line_, "face index 0 is invalid: OBJ indices start at 1");
        if (index < 0 && -index > int64_t(vertex_count_))
            fail(line_, "relative face index " + std::to_string(index) + " reaches before the first vertex (" +
                            std::to_string(vertex_count_) + " defined so far)");
        // A positive index may name a vertex defined further down: checked once the scan is done.
        if (index > largest_index_) {
            largest_index_ = index;
            largest_index_line_ = line_;
        }
    }

    std::string path_;
    size_t line_ = 0;
    size_t vertex_count_ = 0;
    size_t face_count_ = 0;
    int64_t largest_index_ = 0;
    size_t largest_index_line_ = 0;
    std::vector<GroupStart> groups_;
};

// Opens .mtl files beside the OBJ. tinyobjloader's own reader splits its base directory at
// ':' (a search path), which breaks directories whose name holds one.
class MtlBesideObj : public tinyobj::MaterialReader {
public:
    explicit MtlBesideObj(fs::path directory) : directory_(std::move(directory)) {}

    bool operator()(const std::string& name, std::vector<tinyobj::material_t>* materials,
                    std::map<std::string, int>* ids, std::string* warnings, std::string* errors) override {
        std::ifstream in(directory_ / name);
        if (!in) {
            *warnings += "material file '" + name + "' is absent; using the default colour\n";
            return false;
        }
        tinyobj::LoadMtl(ids, materials, &in, warnings, errors);
        return true;
    }

private:
    fs::path directory_;
};

struct ParsedObj {
    tinyobj::attrib_t attrib;
    std::vector<tinyobj::shape_t> shapes;
    std::vector<tinyobj::material_t> materials;
    std::string warnings;
};

ParsedObj parse_with_tinyobj(const std::string& path, std::string text) {
    ParsedObj parsed;
    std::istringstream stream(std::move(text));
    MtlBesideObj mtl_reader(fs::path(path).parent_path());
    std::string errors;
    // canopy triangulates itself: tinyobjloader's ear clipping can drop triangles of polygons
    // with more than four corners, and the triangle count of a scene must not depend on it.
    const bool ok = tinyobj::LoadObj(&parsed.attrib, &parsed.shapes, &parsed.materials, &parsed.warnings, &errors,
                                     &stream, &mtl_reader, /*triangulate=*/false,
                                     /*default_vcols_fallback=*/false);
    if (!ok || !errors.empty()) throw InputError(path + ": " + errors);
    return parsed;
}

std::vector<Material> to_materials(const std::vector<tinyobj::material_t>& parsed) {
    std::vector<Material> materials;
    for (const tinyobj::material_t& m : parsed)
        materials.push_back({m.name, Vec3(m.diffuse[0], m.diffuse[1], m.diffuse[2]),
                             Vec3(m.emission[0], m.emission[1], m.emission[2])});
    return materials;
}

std::vector<std::string> absent_textures(const std::vector<tinyobj::material_t>& materials,
                                         const fs::path& directory) {
    std::set<std::string> absent;
    for (const tinyobj::material_t& m : materials) {
        for (const std::string* name :
             {&m.ambient_texname, &m.diffuse_texname, &m.specular_texname, &m.specular_highlight_texname,
              &m.bump_texname, &m.displacement_texname, &m.alpha_texname, &m.reflection_texname,
              &m.roughness_texname, &m.metallic_texname, &m.sheen_texname, &m.emissive_texname,
              &m.normal_texname}) {
            std::error_code error;
            if (!name->empty() && !fs::exists(directory / *name, error)) absent.insert(*name);
        }
    }
    return {absent.begin(), absent.end()};
}

// One line on stderr per load, however many problems: a scene with hundreds of textures
// would otherwise bury the output.
void warn_once(const std::string& path, const std::string& tinyobj_warnings,
               const std::vector<std::string>& missing_textures) {
    std::set<std::string> notes;
    std::istringstream lines(tinyobj_warnings);
    for (std::string line; std::getline(lines, line);)
        if (!line.empty()) notes.insert(line);
    if (!missing_textures.empty())
        notes.insert(std::to_string(missing_textures.size()) + " texture file(s) named in the .mtl are absent (" +
                     missing_textures.front() + ", ...); canopy uses no textures");
    if (notes.empty()) return;
    std::string message = "canopy: warning: " + path + ": ";
    for (auto note = notes.begin(); note != notes.end(); ++note) message += (note == notes.begin() ? "" : "; ") + *note;
    std::cerr << message << "\n";
}

// Turns tinyobjloader's faces, in file order, into triangles and objects. Objects follow
// ../shared/scenes/README.md literally: every o/g line starts one, even one that ends up with
// no faces (kept with triangle_count 0, so object counts match the README); a material change
// does not start one. Faces before the first o/g line form an object named after the file.
class MeshAssembly {
public:
    MeshAssembly(Mesh& mesh, std::string file_name, const std::vector<GroupStart>& groups, bool has_materials)
        : mesh_(mesh), file_name_(std::move(file_name)), groups_(groups), has_materials_(has_materials) {}

    void add_shape(const tinyobj::shape_t& shape) {
        size_t first_index = 0;
        for (size_t face = 0; face < shape.mesh.num_face_vertices.size(); ++face) {
            begin_objects_up_to(face_);
            const size_t corners = shape.mesh.num_face_vertices[face];
            add_face(&shape.mesh.indices[first_index], corners, shape.mesh.material_ids[face]);
            first_index += corners;
            ++face_;
        }
    }

    // Starts the groups after the last face (empty objects); returns the number of faces read.
    size_t finish() {
        begin_objects_up_to(size_t(-1));
        return face_;
    }

private:
    void begin_objects_up_to(size_t face) {
        if (face == 0 && mesh_.objects.empty() && (groups_.empty() || groups_.front().first_face > 0))
            begin_object(file_name_);
        for (; next_group_ < groups_.size() && groups_[next_group_].first_face <= face; ++next_group_)
            begin_object(groups_[next_group_].name.empty() ? file_name_ : groups_[next_group_].name);
    }

    void begin_object(std::string name) {
        mesh_.objects.push_back({std::move(name), uint32_t(mesh_.triangles.size()), 0});
    }

    // A fan: exactly corners - 2 triangles, exact for the convex polygons that OBJ files hold.
    void add_face(const tinyobj::index_t* corners, size_t count, int material) {
        for (size_t k = 1; k + 1 < count; ++k) {
            mesh_.triangles.emplace_back(corners[0].vertex_index, corners[k].vertex_index,
                                         corners[k + 1].vertex_index);
            if (has_materials_) mesh_.triangle_material.push_back(uint32_t(material));  // -1: patched later
        }
        mesh_.objects.back().triangle_count = uint32_t(mesh_.triangles.size()) - mesh_.objects.back().first_triangle;
    }

    Mesh& mesh_;
    std::string file_name_;
    const std::vector<GroupStart>& groups_;
    bool has_materials_;
    size_t face_ = 0;        // faces read so far, over all shapes
    size_t next_group_ = 0;  // first entry of groups_ not yet begun
};

// Faces with no (or an unknown) material get a default one, added only when some face needs it.
void patch_default_materials(Mesh& mesh, std::vector<Material>& materials) {
    constexpr auto unset = uint32_t(-1);
    if (std::find(mesh.triangle_material.begin(), mesh.triangle_material.end(), unset) == mesh.triangle_material.end())
        return;
    std::replace(mesh.triangle_material.begin(), mesh.triangle_material.end(), unset, uint32_t(materials.size()));
    materials.push_back({"(default)", Vec3(0.8f)});
}

}  // namespace

Scene load_obj(const std::string& path) {
    std::string text = read_text_file(path);
    ObjScan scan(path);
    scan.run(text);
    ParsedObj parsed = parse_with_tinyobj(path, std::move(text));
    if (parsed.attrib.vertices.size() != 3 * scan.vertex_count())
        throw InputError(path + ": tinyobjloader read " + std::to_string(parsed.attrib.vertices.size() / 3) +
                         " vertices where the file has " + std::to_string(scan.vertex_count()));
    warn_once(path, parsed.warnings, absent_textures(parsed.materials, fs::path(path).parent_path()));

    Scene scene;
    scene.name = fs::path(path).stem().string();
    scene.materials = to_materials(parsed.materials);
    Mesh& mesh = scene.meshes.emplace_back();
    mesh.name = scene.name;
    const std::vector<float>& coordinates = parsed.attrib.vertices;
    for (size_t i = 0; i < coordinates.size(); i += 3)
        mesh.positions.emplace_back(coordinates[i], coordinates[i + 1], coordinates[i + 2]);
    MeshAssembly assembly(mesh, scene.name, scan.groups(), !parsed.materials.empty());
    for (const tinyobj::shape_t& shape : parsed.shapes) assembly.add_shape(shape);
    if (const size_t faces = assembly.finish(); faces != scan.face_count())
        throw InputError(path + ": tinyobjloader read " + std::to_string(faces) + " faces where the file has " +
                         std::to_string(scan.face_count()));
    patch_default_materials(mesh, scene.materials);
    scene.instances.push_back({0, glm::mat4(1.0f)});
    return scene;
}

}  // namespace canopy
