#pragma once
// Helpers for the scenes tests: scratch files, InputError messages, scene invariants.
#include "scenes/loaders.h"

#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

namespace canopy::test {

// A fresh directory under the system temp folder, removed with everything in it at the end.
class TempDir {
public:
    TempDir() {
        static std::atomic<int> counter{0};
        const auto stamp = std::chrono::steady_clock::now().time_since_epoch().count();
        path_ = std::filesystem::temp_directory_path() /
                ("canopy-scenes-test-" + std::to_string(stamp) + "-" + std::to_string(counter++));
        std::filesystem::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ignored;
        std::filesystem::remove_all(path_, ignored);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    std::string file(const std::string& name) const { return (path_ / name).string(); }

    std::string write(const std::string& name, const std::string& text) const {
        std::ofstream(path_ / name, std::ios::binary) << text;
        return file(name);
    }

private:
    std::filesystem::path path_;
};

// The message of the canopy::InputError that `load` throws; the test fails on anything else.
template <class Load>
std::string input_error_of(Load&& load) {
    try {
        load();
    } catch (const InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        FAIL("expected canopy::InputError, got another exception: " << e.what());
    }
    FAIL("expected canopy::InputError, nothing was thrown");
    return {};
}

// Captures what is written to std::cerr while it lives.
class CaptureStderr {
public:
    CaptureStderr() : previous_(std::cerr.rdbuf(captured_.rdbuf())) {}
    ~CaptureStderr() { std::cerr.rdbuf(previous_); }
    CaptureStderr(const CaptureStderr&) = delete;
    CaptureStderr& operator=(const CaptureStderr&) = delete;
    std::string text() const { return captured_.str(); }

private:
    std::ostringstream captured_;
    std::streambuf* previous_;
};

// What every loader promises: valid indices, objects contiguous (possibly empty: an OBJ group
// with no faces) and covering every triangle in order, per-triangle materials either absent or complete and in range.
inline void check_mesh_invariants(const Scene& scene) {
    REQUIRE_FALSE(scene.instances.empty());
    for (const Instance& instance : scene.instances) REQUIRE(instance.mesh < scene.meshes.size());
    for (const Mesh& mesh : scene.meshes) {
        for (const glm::uvec3& t : mesh.triangles)
            REQUIRE((t.x < mesh.positions.size() && t.y < mesh.positions.size() && t.z < mesh.positions.size()));
        uint32_t next = 0;
        for (const Object& object : mesh.objects) {
            REQUIRE(object.first_triangle == next);
            next += object.triangle_count;
        }
        REQUIRE(next == mesh.triangles.size());
        if (!mesh.triangle_material.empty()) {
            REQUIRE(mesh.triangle_material.size() == mesh.triangles.size());
            for (uint32_t m : mesh.triangle_material) REQUIRE(m < scene.materials.size());
        }
    }
}

inline bool contains(const BBox& box, const Vec3& p) {
    return p.x >= box.lower.x && p.y >= box.lower.y && p.z >= box.lower.z && p.x <= box.upper.x &&
           p.y <= box.upper.y && p.z <= box.upper.z;
}

}  // namespace canopy::test
