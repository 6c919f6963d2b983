#pragma once
// The processes of a job (`mpirun -n N canopy ...`, Slurm's `srun`) as canopy's commands see them: ranks that
// each run the whole command on their share of the work (samples of an image, whole scenes), and rank 0, which
// gathers the shares and writes the report. Two implementations: distributed_mpi.cpp (Open MPI) and
// distributed_local.cpp (one process: built without MPI, or started without a launcher), so commands hold no
// #if. Every function here is collective unless it says otherwise: all ranks call it, in the same order.
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace canopy::distributed {

// Joins the job when an MPI launcher started this process (and leaves it on destruction); otherwise, or when
// built without MPI, the process is a job of one rank. Construct once, first thing in main().
class Session {
public:
    Session(int& argc, char**& argv);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};

// Not collective.
int rank();   // 0 in one process
int ranks();  // 1 in one process
inline bool is_root() { return rank() == 0; }
std::string host();  // this process's host name
// " (rank R on HOST)" in a job of several ranks, "" in one process: appended to what a rank reports.
std::string where();

// An error that one rank raised, known to every rank of the job (thrown by `checked` on all of them). `usage`: it
// was a std::invalid_argument there, an option at fault, which the command exits on with its usage status.
class JobError : public std::runtime_error {
public:
    JobError(int failed_rank, const std::string& message, bool usage)
        : std::runtime_error(message), failed_rank(failed_rank), usage(usage) {}
    int failed_rank;
    bool usage;
};

// Runs `work` on every rank, then agrees whether it failed anywhere: if it threw on any rank, every rank throws
// JobError with the message of the lowest rank that failed. The point where a rank's bad input stops the whole
// job instead of leaving the others waiting for it. In one process, `work`'s exception propagates unchanged.
void checked(const std::function<void()>& work);

// Rank 0's value on every rank.
bool broadcast_from_root(bool value);
// The sum over ranks, on rank 0 (other ranks get their own value back).
uint64_t sum_to_root(uint64_t value);
// Every rank's text on rank 0, in rank order; other ranks get an empty vector.
std::vector<std::string> gather_to_root(const std::string& text);

// A float array and a key that says what it holds (its sender's numbering), as a rank sends it to rank 0.
struct Part {
    uint64_t key = 0;
    std::vector<float> values;
};
// Every rank's parts to rank 0: `consume` runs on rank 0 for rank 0's parts, then rank 1's, and so on, each
// rank's in its own order, holding one received part at a time. Other ranks only send.
void gather_parts_to_root(std::vector<Part> mine, const std::function<void(Part&&)>& consume);

// Not collective: ends every process of the job with `code`. The last resort, for an error that one rank met
// outside `checked`, where the other ranks may wait for it forever; in one process, exits.
[[noreturn]] void abort_job(int code);

}  // namespace canopy::distributed
