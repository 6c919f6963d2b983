#pragma once
// `canopy reproduce PAPER`: a paper's tables measured again on this machine and written to docs/papers/PAPER.md
// with the paper's printed figures beside canopy's, the command, date, machine and commit; the rows as JSON beside it.
#include <nlohmann/json.hpp>

#include <limits>
#include <string>
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

// What each paper's document says about where and when it was measured.
struct Provenance {
    std::string command, date, machine, commit;
};
Provenance provenance(const std::string& command);
// The document's first sentences: the command, date, machine and commit.
std::string provenance_text(const Provenance& where);

// A figure a paper or a run does not have (printed as "-").
inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();
// `key` of a JSON row as a number; kNotMeasured when absent or null.
double json_number(const nlohmann::json& row, const char* key);

// `out_dir`/`paper`.md and .json, on rank 0.
void write_paper(const std::string& out_dir, const std::string& paper, const std::string& markdown, const nlohmann::json& raw);

// A Markdown table: a header row, then rows of cells.
std::string markdown_table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows);
std::string format(const char* fmt, double value);  // "-" for NaN

// The papers, one file each (reproduce_PAPER.cpp): measure, then write `out_dir`/PAPER.md and .json.
void reproduce_ernst_greiner_2007(const ReproduceOptions& options);
void reproduce_aila_karras_laine_2013(const ReproduceOptions& options);
void reproduce_benthin_2017(const ReproduceOptions& options);
void reproduce_ganestam_doggett_2016(const ReproduceOptions& options);

}  // namespace canopy
