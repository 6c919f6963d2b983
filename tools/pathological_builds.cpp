// pathological_builds: every builder's binary-tree build time on each pathological scene (scenes/pathological.h)
// against its time on as many random triangles, as a Markdown table. Each build runs in a child process of its
// own, so one stopped at LIMIT times its random-triangle time (or that failed) cannot hold up or corrupt the rest.
//   pathological_builds [TRIANGLES=1000000] [BUILDERS=all, or a comma list] [LIMIT=5] [SCENES=all, or a comma list]
#include "accel/builder.h"
#include "scenes/pathological.h"

#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

using namespace canopy;

namespace {

struct Outcome {
    enum Kind { Built, Stopped, Failed } kind;
    double seconds = 0.0;
    std::string message;  // a failure's reason
};

void send(int fd, const std::string& line) {
    for (size_t done = 0; done < line.size();) {
        const ssize_t n = write(fd, line.data() + done, line.size() - done);
        if (n <= 0) return;
        done += size_t(n);
    }
}

// The child: makes the scene and its PrimRefs untimed, says "ready", builds, then says "built SECONDS" or
// "failed MESSAGE".
[[noreturn]] void build_in_child(int fd, const BuilderEntry& builder, std::vector<Triangle> (*make)(size_t), size_t n) {
    try {
        const std::vector<Triangle> tris = make(n);
        BuildInput input{tris, make_prim_refs(tris)};
        send(fd, "ready\n");
        const auto start = std::chrono::steady_clock::now();
        const Bvh bvh = builder.build(std::move(input), BuildSettings{});
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        send(fd, "built " + std::to_string(seconds) + "\n");
    } catch (const std::exception& e) {
        send(fd, std::string("failed ") + e.what() + "\n");
    }
    _exit(0);
}

// One line from the child, or nothing once `seconds` pass (negative: wait as long as it takes) or it dies.
std::optional<std::string> read_line(int fd, double seconds, std::string& pending) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    for (;;) {
        if (const size_t end = pending.find('\n'); end != std::string::npos) {
            std::string line = pending.substr(0, end);
            pending.erase(0, end + 1);
            return line;
        }
        int wait_ms = -1;
        if (seconds >= 0) {
            const double left = std::chrono::duration<double, std::milli>(deadline - std::chrono::steady_clock::now()).count();
            if (left <= 0) return std::nullopt;
            wait_ms = int(left) + 1;
        }
        pollfd p{fd, POLLIN, 0};
        if (poll(&p, 1, wait_ms) <= 0) continue;
        char buffer[512];
        const ssize_t n = read(fd, buffer, sizeof buffer);
        if (n <= 0) return std::nullopt;
        pending.append(buffer, size_t(n));
    }
}

// The build's time, a stop at `limit` seconds of building (negative: none), or the child's failure.
Outcome time_build(const BuilderEntry& builder, std::vector<Triangle> (*make)(size_t), size_t n, double limit) {
    int fds[2];
    if (pipe(fds) != 0) throw std::runtime_error("pipe failed");
    const pid_t child = fork();
    if (child < 0) throw std::runtime_error("fork failed");
    if (child == 0) close(fds[0]), build_in_child(fds[1], builder, make, n);
    close(fds[1]);
    std::string pending;
    Outcome outcome{Outcome::Failed, 0.0, "the build process died"};
    if (const auto ready = read_line(fds[0], -1.0, pending); ready && *ready == "ready") {
        const auto line = read_line(fds[0], limit, pending);
        if (!line) outcome = {Outcome::Stopped, limit, ""};
        else if (line->rfind("built ", 0) == 0) outcome = {Outcome::Built, std::stod(line->substr(6)), ""};
        else if (line->rfind("failed ", 0) == 0) outcome = {Outcome::Failed, 0.0, line->substr(7)};
    } else if (ready && ready->rfind("failed ", 0) == 0) {
        outcome = {Outcome::Failed, 0.0, ready->substr(7)};
    }
    kill(child, SIGKILL);
    waitpid(child, nullptr, 0);
    close(fds[0]);
    return outcome;
}

std::string format(const char* pattern, double value) {
    char text[64];
    std::snprintf(text, sizeof text, pattern, value);
    return text;
}

// A build's cell: its time and its ratio to `random_seconds` (none when 0).
std::string cell(const Outcome& o, double random_seconds) {
    if (o.kind == Outcome::Failed) return "refused: " + o.message;
    if (o.kind == Outcome::Stopped) return format("stopped at %.1f s", o.seconds);
    return format("%.2f s", o.seconds) + (random_seconds > 0 ? format(" (%.2fx)", o.seconds / random_seconds) : "");
}

// The scenes named in `list` ("zero area,needles"), in the table's order; all for "all".
std::vector<PathologicalScene> chosen_scenes(const std::string& list) {
    std::vector<PathologicalScene> chosen;
    for (const PathologicalScene& s : pathological_scenes())
        if (list == "all" || ("," + list + ",").find("," + s.name + ",") != std::string::npos) chosen.push_back(s);
    if (chosen.empty()) throw std::invalid_argument("no pathological scene is named in '" + list + "'");
    return chosen;
}

std::vector<const BuilderEntry*> chosen_builders(const std::string& list) {
    std::vector<const BuilderEntry*> chosen;
    if (list == "all") {
        for (const BuilderEntry& b : builders()) chosen.push_back(&b);
        return chosen;
    }
    std::stringstream names(list);
    for (std::string name; std::getline(names, name, ',');) chosen.push_back(&find_builder(name));
    return chosen;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const size_t n = argc > 1 ? std::stoul(argv[1]) : 1'000'000;
        const std::vector<const BuilderEntry*> chosen = chosen_builders(argc > 2 ? argv[2] : "all");
        const double limit = argc > 3 ? std::stod(argv[3]) : 5.0;
        const std::vector<PathologicalScene> scenes = chosen_scenes(argc > 4 ? argv[4] : "all");
        std::printf("| builder | random |");
        for (const PathologicalScene& s : scenes) std::printf(" %s |", s.name.c_str());
        std::printf("\n|---|---|");
        for (size_t i = 0; i < scenes.size(); ++i) std::printf("---|");
        std::printf("\n");
        for (const BuilderEntry* builder : chosen) {
            const Outcome random = time_build(*builder, random_triangles, n, -1.0);
            std::printf("| %s | %s |", builder->name.c_str(), cell(random, 0.0).c_str());
            std::fflush(stdout);
            for (const PathologicalScene& s : scenes) {
                const double stop = random.kind == Outcome::Built ? limit * random.seconds : -1.0;
                std::printf(" %s |", cell(time_build(*builder, s.make, n, stop), random.seconds).c_str());
                std::fflush(stdout);
            }
            std::printf("\n");
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pathological_builds: %s\n", e.what());
        return 1;
    }
}
