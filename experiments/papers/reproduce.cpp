#include "experiments/papers/reproduce.h"
#include "base/output_path.h"
#include "experiments/build_commit.h"

#include "renderer/distributed.h"
#include "renderer/progress.h"

#include <CLI/CLI.hpp>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <thread>
#include <utility>

namespace canopy {
namespace {

struct Paper {
    const char* name;
    std::optional<PaperDocument> (*reproduce)(const ReproduceOptions&);
};

constexpr Paper kPapers[] = {
    {"ernst-greiner-2007", &reproduce_ernst_greiner_2007},
    {"aila-karras-laine-2013", &reproduce_aila_karras_laine_2013},
    {"benthin-2017", &reproduce_benthin_2017},
    {"ganestam-doggett-2016", &reproduce_ganestam_doggett_2016},
};

std::string first_line_of(const char* command) {
    std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command, "r"), pclose);
    if (!pipe) return "";
    std::array<char, 256> line{};
    if (!std::fgets(line.data(), int(line.size()), pipe.get())) return "";
    std::string text(line.data());
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
    return text;
}

// "AMD EPYC (family 26, model 2)": the model name alone does not tell Zen 4 from Zen 5 on some VMs.
std::string cpu_model() {
    std::ifstream cpuinfo("/proc/cpuinfo");
    std::string name = "unknown CPU", family, model;
    for (std::string line; std::getline(cpuinfo, line) && (name == "unknown CPU" || family.empty() || model.empty());) {
        const std::string value = line.find(':') == std::string::npos ? "" : line.substr(line.find(':') + 2);
        if (line.starts_with("model name")) name = value;
        else if (line.starts_with("cpu family")) family = value;
        else if (line.starts_with("model\t")) model = value;
    }
    return family.empty() ? name : name + " (family " + family + ", model " + model + ")";
}

// What each paper's document says about where and when it was measured.
struct Provenance {
    std::string command, date, machine, commit;
};

Provenance provenance(const std::string& command) {
    const std::time_t now = std::time(nullptr);
    char date[32];
    std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
    const std::string machine = cpu_model() + ", " + std::to_string(std::thread::hardware_concurrency()) +
                                " hardware threads, host " + distributed::host();
    const std::string commit = build_commit();
    return {command, date, machine, commit.empty() ? "unknown (built outside a git checkout)" : commit};
}

// The document's first sentences: the command, date, machine and commit.
std::string provenance_text(const Provenance& where) {
    return "Written by `" + where.command + "` on " + where.date + "; machine: " + where.machine + "; commit " +
           where.commit + ". Do not edit: run the command again.";
}

// `out_dir`/`paper`.md and .json.
void write_paper(const std::string& out_dir, const std::string& paper, const Provenance& where, bool quick,
                 const PaperDocument& document) {
    std::string markdown = "# " + document.title + "\n\n" + provenance_text(where);
    if (quick) markdown += " " + document.quick_note;
    markdown += "\n\n" + document.introduction + "\n\n";
    for (const auto& [heading, body] : document.sections) markdown += "## " + heading + "\n\n" + body;
    std::filesystem::create_directories(out_dir);
    for (const auto& [path, text] : {std::pair{out_dir + "/" + paper + ".md", markdown},
                                     std::pair{out_dir + "/" + paper + ".json", document.raw.dump(2) + "\n"}}) {
        std::ofstream out(path);
        out << text;
        if (!out) throw std::runtime_error(path + ": cannot write");
        std::printf("wrote %s\n", path.c_str());
    }
}

}  // namespace

std::vector<std::string> reproducible_papers() {
    std::vector<std::string> names;
    for (const Paper& paper : kPapers) names.emplace_back(paper.name);
    return names;
}

std::string shared_scene(const ReproduceOptions& options, const std::string& name) {
    return name.starts_with("gen:") ? name : options.scenes_dir + "/" + name + "/scene.json";
}

std::string markdown_table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows) {
    const auto line = [](const std::vector<std::string>& cells) {
        std::string text = "|";
        for (const std::string& cell : cells) text += " " + cell + " |";
        return text + "\n";
    };
    std::string table = line(header) + "|";
    for (size_t i = 0; i < header.size(); ++i) table += "---|";
    table += "\n";
    for (const auto& row : rows) table += line(row);
    return table;
}

void progress_section(const char* paper, const std::string& section) {
    progress::set_context("reproduce " + std::string(paper) + ", " + section);
}

std::string format(const char* fmt, double value) {
    if (std::isnan(value)) return "-";
    std::string text(size_t(std::snprintf(nullptr, 0, fmt, value)), '\0');
    std::snprintf(text.data(), text.size() + 1, fmt, value);
    return text;
}

void run_reproduce(const ReproduceOptions& options) {
    std::vector<const Paper*> chosen;
    std::string known;
    for (const Paper& paper : kPapers) {
        if (options.paper == paper.name || options.paper == "all") chosen.push_back(&paper);
        known += std::string(known.empty() ? "" : ", ") + paper.name;
    }
    if (chosen.empty()) throw std::invalid_argument("reproduce: unknown paper '" + options.paper + "' (known: " + known + ", all)");
    for (const Paper* paper : chosen) {
        const Provenance where = provenance(options.command);  // when the measurement starts
        if (const std::optional<PaperDocument> document = paper->reproduce(options))
            write_paper(options.out_dir, paper->name, where, options.quick, *document);
    }
}

void register_reproduce(CLI::App& canopy, const std::string& command_line) {
    auto rp = std::make_shared<ReproduceOptions>();
    rp->command = command_line;
    struct Run {  // the command's, not the papers' (their benches set their own thread counts within this cap)
        int threads = 0;
        bool quiet = false;
    };
    auto run = std::make_shared<Run>();
    CLI::App* reproduce = canopy.add_subcommand("reproduce", "A paper's tables measured again, written to docs/papers/PAPER.md beside the paper's figures");
    std::string papers;
    for (const std::string& name : reproducible_papers()) papers += name + ", ";
    reproduce->add_option("paper", rp->paper, "Paper: " + papers + "or all")->required();
    reproduce->add_flag("--quick", rp->quick, "Smaller scenes and images, one build and one frame: minutes");
    reproduce->add_option("--out", rp->out_dir, "Folder of PAPER.md and PAPER.json")->capture_default_str();
    reproduce->add_option("--scenes-dir", rp->scenes_dir, "Folder of the shared scenes")->capture_default_str();
    reproduce->add_option("--scenes", rp->scenes, "Your scenes instead of the paper's (no paper figures beside them)")->delimiter(',');
    reproduce->add_option("--threads", run->threads, "Threads for every library (0: all); caps the papers' own counts")
        ->check(CLI::Range(0, 4096));
    reproduce->add_flag("--quiet", run->quiet, kQuietHelp);
    reproduce->callback([rp, run] {
        distributed::checked([&] { if (distributed::is_root()) check_output_folder("--out", rp->out_dir); });
        const auto limit = limit_threads(run->threads);
        progress::start(run->quiet);
        run_reproduce(*rp);
    });
}

}  // namespace canopy
