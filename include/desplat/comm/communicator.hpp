// The communication between the processes (ranks) of one training job (docs/METHOD.md §6,
// batches): sums, broadcasts, a barrier and a job-wide abort, with one process (always built)
// or MPI (built when CMake finds MPI and DESPLAT_WITH_MPI is on).
//
// Contracts every implementation keeps:
// - Every rank calls the collectives (sum, broadcast, barrier) in the same order with the same
//   sizes; a call returns on a rank once that rank's part is done.
// - sum is deterministic for a fixed rank count: every rank ends with the same bits, and a rerun
//   with the same ranks and inputs gives the same bits. The values are added in ascending rank
//   order, ((x₀ + x₁) + x₂) + …, in the array's own type, by our code: MPI only moves the bytes
//   (gather to rank 0, its ordered sum, broadcast back), because MPI_Allreduce may associate
//   floating-point sums differently from call to call (the standard leaves the order open).
// - abort ends every rank of the job and does not return; its message names the rank.
// Not thread-safe: one thread (the one that opened it) calls a communicator.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace desplat {

class Communicator {
 public:
  virtual ~Communicator() = default;
  virtual int rank() const = 0;  // 0 … size() − 1
  virtual int size() const = 0;  // ranks in the job, ≥ 1
  // In place: every rank's `values` becomes the element-wise sum over all ranks.
  virtual void sum(std::span<float> values) = 0;
  virtual void sum(std::span<double> values) = 0;
  virtual void sum(std::span<int64_t> values) = 0;
  // Every rank's `bytes` becomes rank `root`'s (same length on every rank).
  virtual void broadcast(std::span<std::byte> bytes, int root) = 0;
  // Returns once every rank has called it.
  virtual void barrier() = 0;
  // Prints "rank R: message" to stderr and ends every rank of the job with exit status 1.
  [[noreturn]] virtual void abort(const std::string& message) = 0;
  // Which implementation this is: "single process" or "MPI".
  virtual const char* kind() const = 0;
};

// One process: sum and broadcast leave the values as they are, barrier returns at once, abort
// ends this process.
std::unique_ptr<Communicator> single_process_communicator();

// Whether this build has the MPI implementation (DESPLAT_WITH_MPI).
bool built_with_mpi();

// The job's communicator: MPI when this build has it and the process was started by an MPI
// launcher (mpirun, mpiexec or srun: their environment says so), else one process. MPI is
// initialized here (funneled threads: OpenMP inside, MPI from this thread only) and finalized
// when the communicator is destroyed; open at most one per process.
std::unique_ptr<Communicator> open_communicator(int* argc, char*** argv);

}  // namespace desplat
