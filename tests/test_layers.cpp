// The folders are layers and data flows one way (scene file -> Scene -> PrimRefs -> builder -> layout -> kernel ->
// engine -> path tracer -> report): no source includes from a folder its layer may not see, and CMake takes each
// library from its folder whole.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>

namespace fs = std::filesystem;

namespace {

// What each folder may include besides itself: the layers below it, and for the library's users its public header.
const std::map<std::string, std::set<std::string>>& allowed_includes() {
    static const std::map<std::string, std::set<std::string>> allowed = [] {
        std::map<std::string, std::set<std::string>> a;
        const std::vector<std::string> chain = {"base", "scenes", "accel", "kernels", "engine", "renderer", "experiments", "cli"};
        for (size_t i = 0; i < chain.size(); ++i) a[chain[i]] = std::set<std::string>(chain.begin(), chain.begin() + long(i));
        a["tools"] = a["cli"], a["tools"].insert("canopy");              // measurement programs, of the public API too
        a["api"] = a["renderer"], a["api"].insert("canopy");             // the engine alone, and its own header
        a["include"] = {"canopy"}, a["python"] = {"canopy"}, a["examples"] = {"canopy"};
        a["fuzz"] = {"base", "scenes", "accel"};                          // the loaders and their memory check
        return a;
    }();
    return allowed;
}

std::string top_folder(const fs::path& relative) { return relative.begin()->string(); }

// Calls f(path relative to root) for every file under root, skipping build trees and hidden folders.
template <class F>
void for_each_source_file(const fs::path& root, F&& f) {
    for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it) {
        const fs::path relative = fs::relative(it->path(), root);
        const std::string top = top_folder(relative);
        if (top.starts_with("build") || top.starts_with(".")) {
            if (it->is_directory()) it.disable_recursion_pending();
            continue;
        }
        if (it->is_regular_file()) f(relative);
    }
}

// "folder/file.h includes other/x.h" for each include of a folder the file's layer may not see.
std::vector<std::string> layer_violations(const fs::path& root) {
    static const std::regex include(R"(^\s*#\s*include\s*["<]([A-Za-z_]+)/[^">]+[">])");
    std::vector<std::string> violations;
    for_each_source_file(root, [&](const fs::path& relative) {
        const std::string ext = relative.extension().string();
        const auto layer = allowed_includes().find(top_folder(relative));
        if ((ext != ".h" && ext != ".cpp") || layer == allowed_includes().end()) return;  // tests: any layer
        std::ifstream in(root / relative);
        std::smatch m;
        for (std::string line; std::getline(in, line);) {
            if (!std::regex_search(line, m, include)) continue;
            const std::string target = m[1];
            const bool known = allowed_includes().count(target) || target == "canopy";
            if (known && target != layer->first && !layer->second.count(target))
                violations.push_back(relative.string() + " includes " + target + "/");
        }
    });
    return violations;
}

}  // namespace

TEST_CASE("no source includes from a layer above its own", "[layers]") {
    const fs::path root = CANOPY_SOURCE_DIR;
    REQUIRE(fs::exists(root / "engine"));
    const std::vector<std::string> violations = layer_violations(root);
    for (const std::string& v : violations) UNSCOPED_INFO(v);
    CHECK(violations.empty());
}

TEST_CASE("each library is its folder's sources, with no file carved out", "[layers]") {
    const fs::path root = CANOPY_SOURCE_DIR;
    for_each_source_file(root, [&](const fs::path& relative) {
        if (relative.filename() != "CMakeLists.txt") return;
        std::ifstream in(root / relative);
        const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        INFO(relative.string());
        CHECK(text.find("REMOVE_ITEM") == std::string::npos);
    });
}

TEST_CASE("the layer check finds an include from above", "[layers]") {
    const fs::path root = fs::temp_directory_path() / "canopy_layers_test";
    fs::remove_all(root);
    fs::create_directories(root / "scenes");
    std::ofstream(root / "scenes" / "bad.h") << "#pragma once\n#include \"engine/accelerator.h\"\n#include \"base/geometry.h\"\n";
    const std::vector<std::string> violations = layer_violations(root);
    REQUIRE(violations.size() == 1);
    CHECK(violations[0] == "scenes/bad.h includes engine/");
    fs::remove_all(root);
}
