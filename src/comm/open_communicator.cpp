// Which communicator a process gets (communicator.hpp).
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "comm/mpi_communicator.hpp"
#include "desplat/comm/communicator.hpp"

namespace desplat {

bool built_with_mpi() {
#if DESPLAT_WITH_MPI
  return true;
#else
  return false;
#endif
}

namespace {
// A positive count from the environment, or 0 when absent or not a number.
int count_from(const std::function<const char*(const char*)>& getenv, const char* name) {
  const char* text = getenv(name);
  if (!text) return 0;
  char* end = nullptr;
  const long n = std::strtol(text, &end, 10);
  return end != text && *end == '\0' && n > 0 && n < (1L << 30) ? int(n) : 0;
}
}  // namespace

LaunchEnvironment read_launch_environment(const std::function<const char*(const char*)>& getenv, bool with_mpi) {
  LaunchEnvironment launch;
  launch.mpi = getenv("OMPI_COMM_WORLD_SIZE") || getenv("PMI_RANK") || getenv("PMI_SIZE") || getenv("PMIX_RANK");
  // srun sets SLURM_STEP_NUM_TASKS in every task of a job step; an sbatch script has none.
  const int slurm_tasks = count_from(getenv, "SLURM_STEP_NUM_TASKS");
  for (int n : {count_from(getenv, "OMPI_COMM_WORLD_SIZE"), count_from(getenv, "PMI_SIZE"), slurm_tasks})
    if (n > 0) {
      launch.tasks = n;
      break;
    }
  const std::string n = std::to_string(launch.tasks);
  if (launch.tasks > 1 && !with_mpi)
    launch.error = "started as " + n +
                   " processes, but this build has no MPI, so each would train alone into the same output folder; "
                   "rebuild with MPI (install libopenmpi-dev, then configure again) or start one process";
  else if (launch.tasks > 1 && !launch.mpi)
    launch.error = "started by srun as " + n +
                   " tasks without an MPI plugin that Open MPI can join; run srun --mpi=pmix (or set MpiDefault=pmix "
                   "in slurm.conf)";
  return launch;
}

void broadcast_string(Communicator& comm, std::string& text, int root) {
  std::vector<char> bytes(text.begin(), text.end());
  broadcast_vector(comm, bytes, root);
  text.assign(bytes.begin(), bytes.end());
}

std::unique_ptr<Communicator> open_communicator(int* argc, char*** argv) {
  const LaunchEnvironment launch = read_launch_environment(std::getenv, built_with_mpi());
  if (!launch.error.empty()) throw std::runtime_error(launch.error);
#if DESPLAT_WITH_MPI
  if (launch.mpi) return mpi_communicator(argc, argv);
#else
  (void)argc, (void)argv;
#endif
  return single_process_communicator();
}

}  // namespace desplat
