#pragma once
// Commands over several scenes (study, bench) under a job of several ranks (renderer/distributed.h): whole
// scenes go to ranks, so that every accelerator of a scene is built and timed in one process and every ratio
// between them still comes from one run on one machine; rank 0 gathers what each scene reported.
#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace canopy {

// What a command says about one scene: printed at once by rank 0 (and in one process), kept by other ranks
// until rank 0 prints it in the scenes' order.
class SceneReport {
public:
    explicit SceneReport(bool live) : live_(live) {}
    void printf(const char* format, ...) __attribute__((format(printf, 2, 3)));
    void flush();  // a long command shows each line as it comes
    const std::string& text() const { return text_; }

private:
    bool live_;
    std::string text_;
};

// A scene's measurement once the scene is loaded: it prints to the report and returns the scene's JSON.
using SceneWork = std::function<nlohmann::json(SceneReport&)>;

// For each scene, `load` and then the work it returns, scene i on rank (i mod ranks), a round of `ranks` scenes at
// a time; returns on rank 0 every scene's JSON in the scenes' order, each scene's report printed before it is
// returned (other ranks get nothing). The ranks agree after a round's loads and again after its work: a scene
// that cannot be loaded stops the job on every rank with its rank's message (distributed::JobError) before any
// other rank measures. Collective.
std::vector<nlohmann::json> run_per_scene(const std::vector<std::string>& scenes,
                                          const std::function<SceneWork(const std::string&)>& load);

}  // namespace canopy
