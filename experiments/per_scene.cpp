#include "experiments/per_scene.h"

#include "renderer/distributed.h"
#include "renderer/progress.h"

#include <cstdarg>
#include <cstdio>
#include <optional>

namespace canopy {

void SceneReport::printf(const char* format, ...) {
    va_list args;
    va_start(args, format);
    if (live_) {
        progress::clear();  // a terminal's progress line, so the text starts on a line of its own
        std::vprintf(format, args);
    } else {
        va_list size_args;
        va_copy(size_args, args);
        const int size = std::vsnprintf(nullptr, 0, format, size_args);
        va_end(size_args);
        const size_t old = text_.size();
        text_.resize(old + size_t(size) + 1);
        std::vsnprintf(text_.data() + old, size_t(size) + 1, format, args);
        text_.resize(old + size_t(size));
    }
    va_end(args);
}

void SceneReport::flush() {
    if (live_) std::fflush(stdout);
}

std::vector<nlohmann::json> run_per_scene(const std::vector<std::string>& scenes,
                                          const std::function<SceneWork(const std::string&)>& load) {
    const size_t ranks = size_t(distributed::ranks()), rank = size_t(distributed::rank());
    std::vector<nlohmann::json> results;
    for (size_t round = 0; round * ranks < scenes.size(); ++round) {
        const size_t mine = round * ranks + rank;
        SceneWork work;
        distributed::checked([&] {
            if (mine < scenes.size()) work = load(scenes[mine]);
        });
        SceneReport report(distributed::is_root());  // rank 0's scene is the round's first: it prints at once
        std::optional<nlohmann::json> result;
        distributed::checked([&] {
            if (work) result = work(report);
        });
        const nlohmann::json sent = result ? nlohmann::json{{"report", report.text()}, {"result", *result}} : nullptr;
        for (const std::string& received : distributed::gather_to_root(sent.dump())) {
            const nlohmann::json scene = nlohmann::json::parse(received);
            if (scene.is_null()) continue;
            std::fputs(scene.at("report").get<std::string>().c_str(), stdout);
            results.push_back(scene.at("result"));
        }
        std::fflush(stdout);
    }
    return results;
}

}  // namespace canopy
