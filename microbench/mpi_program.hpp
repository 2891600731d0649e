#pragma once
// What every MPI benchmark's main needs: only rank 0 speaks and writes, a bad output path fails
// on every rank with the same exit code before any work, and MPI is finalised on every path.
#include "sphperf/errors.hpp"
#include "sphperf/report.hpp"

#include <mpi.h>

#include <filesystem>
#include <iostream>
#include <optional>
#include <string>

namespace sphperf {

// Rank 0 checks the report path, then tells the others; all leave with exit 2 when it is bad.
inline void check_report_path_on_root(const std::optional<std::filesystem::path> &path, int rank) {
    int ok = 1;
    std::string error;
    if (rank == 0 && path) {
        try {
            JsonSink::check_writable(*path);
        } catch (const UsageError &e) {
            ok = 0;
            error = e.what();
        }
    }
    MPI_Bcast(&ok, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (!ok) {
        if (rank == 0)
            throw UsageError(error);
        throw ExitRequest{exit_usage};
    }
}

// Point-to-point benchmarks need a partner: a single rank is refused with the command to use.
inline void require_ranks(const std::string &program, int size, int minimum = 2) {
    if (size < minimum)
        throw UsageError(program + " needs at least " + std::to_string(minimum) +
                         " MPI ranks, got " + std::to_string(size) +
                         " (run it with scripts/mpirun.sh -n " + std::to_string(minimum) + " ...)");
}

// MPI_Init, the body run(argc, argv, rank, size) under guarded_main (rank 0 alone prints), and
// MPI_Finalize.
template <class Run> int mpi_program(const char *name, int argc, char **argv, Run &&run) {
    MPI_Init(&argc, &argv);
    int rank = 0, size = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    const int code = guarded_main(rank == 0 ? name : "", [&] {
        if (rank != 0) {
            std::cout.setstate(std::ios::failbit);
            std::cerr.setstate(std::ios::failbit);
        }
        return run(argc, argv, rank, size);
    });
    MPI_Finalize();
    return code;
}

} // namespace sphperf
