#pragma once
// `canopy reproduce PAPER`: a paper's tables measured again on this machine and written to docs/papers/PAPER.md
// with the paper's printed figures beside canopy's, the command, date, machine and commit; the rows as JSON beside it.
#include "experiments/command.h"

#include <nlohmann/json.hpp>

#include <limits>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace canopy {

struct ReproduceOptions {
    std::string paper;                     // a name of reproducible_papers(), or "all"
    bool quick = false;                    // smaller scenes and frames: minutes, for tests and a first look
    std::string out_dir = "docs/papers";   // PAPER.md and PAPER.json go here
    std::string scenes_dir = "../shared/scenes";
    std::vector<std::string> scenes;       // instead of the paper's scenes (no paper figures beside them)
    std::string command;                   // the command line, quoted in the document
};

void run_reproduce(const ReproduceOptions& options);
std::vector<std::string> reproducible_papers();
// `canopy reproduce`, its options and its run; `command_line` is quoted in the documents.
void register_reproduce(CLI::App& canopy, const std::string& command_line);

// A scene of a reproduction: how the document names it, its scene.json path or generator spec, and the paper's
// figures for it (none for a user's scene or a stand-in the paper has no row for).
template <class Figures>
struct Subject {
    std::string label, spec;
    const Figures* paper = nullptr;
};

// A scene of a paper's list: a shared scene's folder name or a generator spec (gen:...) in full and in --quick
// runs (nullptr: not in that run), its label in each, and the paper's figures for it.
template <class Figures>
struct PaperSubject {
    const char* label;
    const char* full;
    const char* quick;
    const Figures* paper = nullptr;
    const char* quick_label = nullptr;  // nullptr: label
};

// `name` under --scenes-dir (NAME/scene.json), or a generator spec as it is.
std::string shared_scene(const ReproduceOptions& options, const std::string& name);

// The user's --scenes, each labelled by its spec and without paper figures, or else the paper's list for a full
// or a --quick run.
template <class Figures>
std::vector<Subject<Figures>> subjects(const ReproduceOptions& options, std::span<const PaperSubject<Figures>> list) {
    std::vector<Subject<Figures>> chosen;
    for (const std::string& spec : options.scenes) chosen.push_back({spec, spec, nullptr});
    if (!chosen.empty()) return chosen;
    for (const PaperSubject<Figures>& s : list) {
        const char* scene = options.quick ? s.quick : s.full;
        if (scene) chosen.push_back({options.quick && s.quick_label ? s.quick_label : s.label, shared_scene(options, scene), s.paper});
    }
    return chosen;
}

// A builder of a paper and canopy's builder for it.
struct PaperBuilder {
    const char* paper;
    const char* canopy;

    std::string label() const { return std::string(paper) + " (" + canopy + ")"; }  // "SBVH (sbvh)"
};

// A reproduction's document: PAPER.md under its title and the command, date, machine and commit that wrote it,
// then its sections; its measurements as PAPER.json beside it.
struct PaperDocument {
    std::string title;
    std::string quick_note;    // a sentence on what a --quick run leaves out
    std::string introduction;  // what the paper measured and what canopy measures instead
    std::vector<std::pair<std::string, std::string>> sections;  // "## heading" and its Markdown
    nlohmann::json raw;
};

// A figure a paper or a run does not have (printed as "-").
inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

// Names what a paper measures next on the progress line ("reproduce benthin-2017, Table 3: ..."), before the
// bench or study it runs adds its own scene, row and step.
void progress_section(const char* paper, const std::string& section);

// A Markdown table: a header row, then rows of cells.
std::string markdown_table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows);
std::string format(const char* fmt, double value);  // "-" for NaN

// The papers, one file each (reproduce_PAPER.cpp): measure (collective), and on rank 0 return the document.
std::optional<PaperDocument> reproduce_ernst_greiner_2007(const ReproduceOptions& options);
std::optional<PaperDocument> reproduce_aila_karras_laine_2013(const ReproduceOptions& options);
std::optional<PaperDocument> reproduce_benthin_2017(const ReproduceOptions& options);
std::optional<PaperDocument> reproduce_ganestam_doggett_2016(const ReproduceOptions& options);

}  // namespace canopy
