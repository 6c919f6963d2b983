// The canopy command: a table of subcommands, each registered by its own file, under MPI when run as a job.
#include "cli/render.h"
#include "experiments/accuracy.h"
#include "experiments/bench.h"
#include "experiments/build_commit.h"
#include "experiments/papers/reproduce.h"
#include "experiments/rays.h"
#include "experiments/study.h"
#include "experiments/tradeoff.h"
#include "renderer/distributed.h"

#include <CLI/CLI.hpp>
#include <malloc.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>

namespace {

using namespace canopy;

// Freed memory stays in the process for the next build instead of going back to the kernel: glibc otherwise maps
// large arrays afresh for every build and unmaps them when freed, and on this project's VM the page faults of
// touching them again cost more than the work (a 2-million-triangle collapse: 0.7 s of faults for 0.1 s of
// writing). Builds after the first reuse the memory; the bench reports the fastest of several builds.
void keep_freed_memory() {
    constexpr int kLargest = 1 << 30;  // allocations up to 1 GiB come from the heap, which is never trimmed below it
    mallopt(M_MMAP_THRESHOLD, kLargest);
    mallopt(M_TRIM_THRESHOLD, kLargest);
}

// `text` as a POSIX shell reads it back: single-quoted when it holds anything but plain characters.
std::string shell_quoted(const std::string& text) {
    const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("_./,=:@%+-", c);
    });
    if (plain) return text;
    std::string quoted = "'";
    for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return quoted + "'";
}

// "canopy ARG ...", quoted as a shell reads it back: the command the reproduced papers' documents name.
std::string command_line(int argc, char** argv) {
    std::string command = "canopy";
    for (int i = 1; i < argc; ++i) command += " " + shell_quoted(argv[i]);
    return command;
}

// One convention for every command, stated in the top-level --help: 2 when the command line is at fault (an unknown or
// malformed option, or options a command cannot act on, which commands throw as std::invalid_argument before any
// work), 1 when the input or the run is (a scene that cannot be read, a write that fails). CLI11's own codes (105,
// 106, 109, ...) told a script nothing it could act on.
constexpr int kRunError = 1, kUsageError = 2;
constexpr const char* kExitCodes =
    "Exit status: 0 done; 1 an input or run error (a scene that cannot be read, a failed write); 2 a usage error (an\n"
    "unknown, malformed or contradicting option, an output path that cannot be written).";

// The project version and the commit the binary was built from, when it was built in a git checkout.
std::string version_text() {
    const std::string commit = build_commit();
    return std::string("canopy ") + CANOPY_VERSION + (commit.empty() ? "" : ", commit " + commit);
}

// What a first word that names no command meant, where it names a feature of one: README and design call these
// helpers, and a new user typed them as commands.
std::string unknown_command(const std::string& word, const CLI::App& app) {
    std::string names;
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
        names += (names.empty() ? "" : ", ") + sub->get_name();
    const std::pair<const char*, const char*> features[] = {
        {"dynamic", "bench --dynamic"}, {"heatmap", "render --heatmap"}, {"plot", "study, tradeoff or accuracy --plot"}};
    std::string text = "unknown command '" + word + "'; the commands are " + names;
    for (const auto& [name, where] : features)
        if (word == name) text += " (" + word + ": " + where + ")";
    return text;
}

}  // namespace

int main(int argc, char** argv) {
    distributed::Session session(argc, argv);  // a job of ranks under mpirun or srun, else this process alone
    keep_freed_memory();
    CLI::App app{"canopy: a CPU ray tracer with pluggable BVH builders, measured against Embree"};
    app.set_version_flag("--version", version_text());
    app.require_subcommand(0, 1);
    app.footer(kExitCodes);
    const std::string command = command_line(argc, argv);
    const std::function<void(CLI::App&)> subcommands[] = {
        register_render, register_bench, register_study, register_tradeoff, register_accuracy, register_rays,
        [&](CLI::App& canopy) { register_reproduce(canopy, command); },
    };
    for (const auto& add : subcommands) add(app);
    const auto named = [&](const CLI::App* sub) { return sub->check_name(argv[1]); };
    if (argc > 1 && argv[1][0] != '-' && app.get_subcommands(named).empty()) {
        if (distributed::is_root()) std::fprintf(stderr, "canopy: error: %s\n", unknown_command(argv[1], app).c_str());
        return kUsageError;
    }
    try {
        app.parse(argc, argv);  // runs the chosen subcommand once its options are parsed
        if (app.get_subcommands().empty()) {
            if (distributed::is_root()) std::fprintf(stderr, "%s", app.help().c_str());
            return kUsageError;
        }
    } catch (const CLI::ParseError& e) {  // every rank parses the same arguments: one says what is wrong
        const int code = distributed::is_root() ? app.exit(e) : e.get_exit_code();
        return code == 0 ? 0 : kUsageError;  // --help and --version are ParseErrors of code 0
    } catch (const distributed::JobError& e) {  // known to every rank: rank 0 says it
        if (distributed::is_root()) std::fprintf(stderr, "canopy: error: %s\n", e.what());
        return e.usage ? kUsageError : kRunError;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "canopy: error: %s%s\n", e.what(), distributed::where().c_str());
        const int code = dynamic_cast<const std::invalid_argument*>(&e) ? kUsageError : kRunError;
        // Other ranks may be waiting for this one: end them too.
        if (distributed::ranks() > 1) distributed::abort_job(code);
        return code;
    }
    return 0;
}
