#pragma once
// Output paths checked before any work, so that a typo in one costs a second instead of the whole run: every
// command that writes a file checks it as it starts, with the extensions its writer takes.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy {

// ".png" for "a/b.PNG": writers choose their format by the extension, whatever its case.
inline std::string lower_extension(const std::string& path) {
    std::string extension = std::filesystem::path(path).extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
    return extension;
}

// Throws std::invalid_argument naming `option` and `path` unless `path` can be written: its folder exists and this
// process may create files in it, it is not itself a folder, and its extension is one of `extensions` (lower case,
// with the dot; any when empty).
inline void check_output_path(const std::string& option, const std::string& path, const std::vector<std::string>& extensions = {}) {
    namespace fs = std::filesystem;
    const std::string named = option + " " + path + ": ";
    const fs::path folder = fs::path(path).parent_path().empty() ? fs::path(".") : fs::path(path).parent_path();
    std::error_code error;
    if (!fs::is_directory(folder, error)) throw std::invalid_argument(named + "no folder " + folder.string());
    if (access(folder.c_str(), W_OK) != 0) throw std::invalid_argument(named + "folder " + folder.string() + " is not writable");
    if (fs::is_directory(path, error)) throw std::invalid_argument(named + "is a folder, not a file");
    if (extensions.empty() || std::find(extensions.begin(), extensions.end(), lower_extension(path)) != extensions.end()) return;
    std::string known;
    for (const std::string& extension : extensions) known += (known.empty() ? "" : ", ") + extension;
    throw std::invalid_argument(named + "the extension must be one of " + known);
}

// As check_output_path for a folder that the command creates with its parents: the folder, or else the nearest
// folder above it that exists, must be writable.
inline void check_output_folder(const std::string& option, const std::string& folder) {
    namespace fs = std::filesystem;
    fs::path existing = fs::absolute(folder);
    std::error_code error;
    while (!fs::exists(existing, error) && existing.has_relative_path()) existing = existing.parent_path();
    if (!fs::is_directory(existing, error))
        throw std::invalid_argument(option + " " + folder + ": " + existing.string() + " is not a folder");
    if (access(existing.c_str(), W_OK) != 0)
        throw std::invalid_argument(option + " " + folder + ": folder " + existing.string() + " is not writable");
}

}  // namespace canopy
