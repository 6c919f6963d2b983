// distributed.h for a build without MPI: every job is this one process, rank 0 of 1.
#include "renderer/distributed.h"

#include <unistd.h>

#include <cstdlib>

namespace canopy::distributed {

Session::Session(int&, char**&) {}
Session::~Session() = default;

int rank() { return 0; }
int ranks() { return 1; }

std::string host() {
    char name[256] = {};
    gethostname(name, sizeof name - 1);
    return name;
}

std::string where() { return ""; }

void checked(const std::function<void()>& work) { work(); }

bool broadcast_from_root(bool value) { return value; }
uint64_t sum_to_root(uint64_t value) { return value; }
std::vector<std::string> gather_to_root(const std::string& text) { return {text}; }

void gather_parts_to_root(std::vector<Part> mine, const std::function<void(Part&&)>& consume) {
    for (Part& part : mine) consume(std::move(part));
}

void abort_job(int code) { std::exit(code); }

}  // namespace canopy::distributed
