#pragma once
// What every fuzz target shares: the input written as a file in a directory of this process's own (the loaders
// read paths), and a load that must end in a scene or a clear refusal. InputError (bad input) and MemoryError
// (too large for the bound) are the expected outcomes; any other exception escapes, aborts, and is a finding,
// as is every crash, leak, hang and sanitizer report.
#include "accel/memory_budget.h"
#include "scenes/loaders.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <unistd.h>

namespace canopy::fuzz {

// Builds whose estimate exceeds this are refused, so a small input cannot ask for gigabytes (gen:...?tris=4e8, a
// scene.json placing a mesh a million times): the fuzzer's -rss_limit_mb stays for real leaks and runaways.
constexpr uint64_t kMemoryBound = 256ull << 20;

// This process's scratch directory, created on first use; libFuzzer's -jobs and -fork run several processes.
inline const std::filesystem::path& scratch_directory() {
    static const std::filesystem::path directory = [] {
        auto path = std::filesystem::temp_directory_path() / ("canopy-fuzz-" + std::to_string(getpid()));
        std::filesystem::create_directories(path);
        return path;
    }();
    return directory;
}

inline std::filesystem::path write_file(const std::string& name, std::string_view bytes) {
    const std::filesystem::path path = scratch_directory() / name;
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
    return path;
}

// Loads as canopy render does, with the memory check, and flattens what fits, as every command does next.
inline void load_and_flatten(const std::string& name, uint64_t memory_bound = kMemoryBound) {
    const BuildPlan plan;
    const MemoryAvailable bound{memory_bound, "the fuzz target's bound"};
    try {
        const Scene scene = load_scene(name, [&](const SceneSize& size) {
            require_memory(name, estimate_memory(size, {&plan, 1}), bound);
        });
        const FlatScene flat = flatten(scene);
        (void)auto_camera(flat.bounds);
    } catch (const InputError&) {
    } catch (const MemoryError&) {
    }
}

inline std::string_view as_text(const uint8_t* data, size_t size) {
    return {reinterpret_cast<const char*>(data), size};
}

}  // namespace canopy::fuzz
