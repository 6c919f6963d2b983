#pragma once
// Output paths: what the writers read of them.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>

namespace canopy {

// ".png" for "a/b.PNG": writers choose their format by the extension, whatever its case.
inline std::string lower_extension(const std::string& path) {
    std::string extension = std::filesystem::path(path).extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
    return extension;
}

}  // namespace canopy
