// distributed.h over MPI (Open MPI from Debian; any MPI-3 library).
#include "renderer/distributed.h"

#include <mpi.h>
#include <unistd.h>

#include <cstdlib>
#include <limits>

namespace canopy::distributed {
namespace {

bool joined = false;  // MPI initialised: a launcher started this process
int my_rank = 0, rank_count = 1;

// A launcher sets one of these in every process it starts: Open MPI's mpirun, PMIx (srun --mpi=pmix, newer
// mpiruns), PMI-1/2 (srun --mpi=pmi2, MPICH's hydra). Without one, MPI_Init would start a singleton job, with
// the daemon and sockets that brings, for nothing: the process runs alone, as if built without MPI.
bool started_by_launcher() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
        if (std::getenv(name)) return true;
    return false;
}

void send_bytes(const void* data, size_t bytes, int to) {
    if (bytes > size_t(std::numeric_limits<int>::max())) throw std::length_error("a message of more than 2 GiB");
    MPI_Send(data, int(bytes), MPI_BYTE, to, 0, MPI_COMM_WORLD);
}

void receive_bytes(void* data, size_t bytes, int from) {
    MPI_Recv(data, int(bytes), MPI_BYTE, from, 0, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
}

std::string broadcast_text(std::string text, int from) {
    uint64_t size = text.size();
    MPI_Bcast(&size, 1, MPI_UINT64_T, from, MPI_COMM_WORLD);
    text.resize(size);
    MPI_Bcast(text.data(), int(size), MPI_CHAR, from, MPI_COMM_WORLD);
    return text;
}

}  // namespace

Session::Session(int& argc, char**& argv) {
    if (!started_by_launcher()) return;
    MPI_Init(&argc, &argv);
    joined = true;
    MPI_Comm_rank(MPI_COMM_WORLD, &my_rank);
    MPI_Comm_size(MPI_COMM_WORLD, &rank_count);
}

Session::~Session() {
    if (joined) MPI_Finalize();
}

int rank() { return my_rank; }
int ranks() { return rank_count; }

std::string host() {
    char name[256] = {};
    gethostname(name, sizeof name - 1);
    return name;
}

std::string where() { return ranks() > 1 ? " (rank " + std::to_string(rank()) + " on " + host() + ")" : ""; }

void checked(const std::function<void()>& work) {
    if (ranks() == 1) return work();
    std::string error;
    int usage = 0;
    try {
        work();
    } catch (const JobError&) {
        throw;  // every rank has it already: agreeing again would wait for ranks that are not coming
    } catch (const std::exception& e) {
        error = e.what() + where();
        usage = dynamic_cast<const std::invalid_argument*>(&e) != nullptr;
    }
    const int mine = error.empty() ? ranks() : rank();
    int first = ranks();
    MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (first == ranks()) return;
    error = broadcast_text(error, first);
    MPI_Bcast(&usage, 1, MPI_INT, first, MPI_COMM_WORLD);
    throw JobError(first, error, usage != 0);
}

bool broadcast_from_root(bool value) {
    if (ranks() == 1) return value;
    int v = value;
    MPI_Bcast(&v, 1, MPI_INT, 0, MPI_COMM_WORLD);
    return v != 0;
}

uint64_t sum_to_root(uint64_t value) {
    if (ranks() == 1) return value;
    uint64_t sum = 0;
    MPI_Reduce(&value, &sum, 1, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    return is_root() ? sum : value;
}

std::vector<std::string> gather_to_root(const std::string& text) {
    if (!is_root()) {
        const uint64_t size = text.size();
        send_bytes(&size, sizeof size, 0);
        send_bytes(text.data(), size, 0);
        return {};
    }
    std::vector<std::string> texts{text};
    for (int from = 1; from < ranks(); ++from) {
        uint64_t size = 0;
        receive_bytes(&size, sizeof size, from);
        texts.emplace_back(size, '\0');
        receive_bytes(texts.back().data(), size, from);
    }
    return texts;
}

// A rank sends how many parts it has, then each part's key and size, then its values.
void gather_parts_to_root(std::vector<Part> mine, const std::function<void(Part&&)>& consume) {
    if (!is_root()) {
        const uint64_t count = mine.size();
        send_bytes(&count, sizeof count, 0);
        for (const Part& part : mine) {
            const uint64_t header[2] = {part.key, part.values.size()};
            send_bytes(header, sizeof header, 0);
            send_bytes(part.values.data(), part.values.size() * sizeof(float), 0);
        }
        return;
    }
    for (Part& part : mine) consume(std::move(part));
    for (int from = 1; from < ranks(); ++from) {
        uint64_t count = 0;
        receive_bytes(&count, sizeof count, from);
        for (uint64_t i = 0; i < count; ++i) {
            uint64_t header[2] = {};
            receive_bytes(header, sizeof header, from);
            Part part{header[0], std::vector<float>(header[1])};
            receive_bytes(part.values.data(), header[1] * sizeof(float), from);
            consume(std::move(part));
        }
    }
}

void abort_job(int code) {
    if (joined && ranks() > 1) MPI_Abort(MPI_COMM_WORLD, code);
    std::exit(code);
}

}  // namespace canopy::distributed
