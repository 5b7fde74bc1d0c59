// The communication between the processes (ranks) of one training job (docs/METHOD.md §6,
// batches): sums, broadcasts, a barrier and a job-wide abort, with one process (always built)
// or MPI (built when CMake finds MPI and DESPLAT_WITH_MPI is on).
//
// Contracts every implementation keeps:
// - Every rank calls the collectives (sum, broadcast, barrier) in the same order with the same
//   sizes; a call returns on a rank once that rank's part is done.
// - sum is deterministic for a fixed rank count: every rank ends with the same bits, and a rerun
//   with the same ranks and inputs gives the same bits. The values are added in the order of the
//   rank tree, in the array's own type, by our code: the ranks with an even index sum first, the
//   odd ones sum, then the two sums are added, recursively on the index's next bit, so
//   S(o, s) = S(o, 2s) + S(o + s, 2s) over ranks o, o + s, o + 2s, … (a part with no rank is left
//   out) and the job's sum is S(0, 1): x₀ + x₁ for 2 ranks, (x₀ + x₂) + (x₁ + x₃) for 4. With N a
//   power of two this is the order in which one process adds a batch's views (sum_in_view_tree,
//   docs/METHOD.md §6, ranks). MPI only moves the bytes (gather to rank 0, its ordered sum,
//   broadcast back), because MPI_Allreduce may associate floating-point sums differently from
//   call to call (the standard leaves the order open).
// - abort ends every rank of the job and does not return; its message names the rank.
// Not thread-safe: one thread (the one that opened it) calls a communicator.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace desplat {

// What one rank's collectives cost since its communicator opened: the payload bytes of every
// call (the array's size, for sum and broadcast alike) and the wall seconds spent inside them.
// A one-process communicator moves nothing and counts nothing.
struct CommTotals {
  int64_t bytes = 0;
  double seconds = 0;
  int64_t calls = 0;
};

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
  CommTotals totals() const { return totals_; }

 protected:
  CommTotals totals_;
};

// Collective: whether `flag` is set on any rank (on `comm`, or this process's when null).
inline bool any_rank(Communicator* comm, bool flag) {
  if (!comm || comm->size() == 1) return flag;
  int64_t n = flag;
  comm->sum(std::span<int64_t>(&n, 1));
  return n > 0;
}

// Collectives over values of any layout, built on broadcast (every rank passes its own
// value; every rank returns with root's). The vector's length travels first.
void broadcast_string(Communicator& comm, std::string& text, int root);
template <typename T>
void broadcast_vector(Communicator& comm, std::vector<T>& values, int root) {
  int64_t n = int64_t(values.size());
  comm.broadcast(std::as_writable_bytes(std::span<int64_t>(&n, 1)), root);
  values.resize(size_t(n));
  comm.broadcast(std::as_writable_bytes(std::span<T>(values)), root);
}

// One process: sum and broadcast leave the values as they are, barrier returns at once, abort
// ends this process.
std::unique_ptr<Communicator> single_process_communicator();

// Whether this build has the MPI implementation (DESPLAT_WITH_MPI).
bool built_with_mpi();

// How a process was started, read from its environment (`getenv`, or a test's table):
// - `mpi`: by a launcher MPI can join, whose variables say so (mpirun's OMPI_COMM_WORLD_SIZE,
//   PMI_RANK/PMI_SIZE of Hydra and Slurm's pmi2, PMIX_RANK of srun --mpi=pmix);
// - `tasks`: how many processes that launch started (1 when it does not say);
// - `error`: why it cannot run, empty if it can: several processes but this build has no MPI
//   (each would train alone into the same output), or srun's tasks without an MPI plugin
//   (Debian's Open MPI joins srun only through PMIx: MPI_Init would fail).
// srun with one task, and an sbatch script (SLURM_PROCID without a job step), are one process.
struct LaunchEnvironment {
  bool mpi = false;
  int tasks = 1;
  std::string error;
};
LaunchEnvironment read_launch_environment(const std::function<const char*(const char*)>& getenv, bool with_mpi);

// The job's communicator: MPI when read_launch_environment says so, else one process; a
// launch that cannot run throws std::runtime_error with its `error`. MPI is initialized here
// (funneled threads: OpenMP inside, MPI from this thread only) and finalized when the
// communicator is destroyed; open at most one per process.
std::unique_ptr<Communicator> open_communicator(int* argc, char*** argv);

}  // namespace desplat
