// Which communicator a process gets (communicator.hpp).
#include <cstdlib>

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
// Set by the launchers: Open MPI's mpirun, MPICH/Hydra and Intel MPI (PMI), Slurm's srun (PMI
// or PMIx). A plain start has none of them, and then MPI is not initialized at all.
bool started_by_mpi_launcher() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID"})
    if (std::getenv(name)) return true;
  return false;
}
}  // namespace

void broadcast_string(Communicator& comm, std::string& text, int root) {
  std::vector<char> bytes(text.begin(), text.end());
  broadcast_vector(comm, bytes, root);
  text.assign(bytes.begin(), bytes.end());
}

std::unique_ptr<Communicator> open_communicator(int* argc, char*** argv) {
#if DESPLAT_WITH_MPI
  if (started_by_mpi_launcher()) return mpi_communicator(argc, argv);
#else
  (void)argc, (void)argv;
#endif
  return single_process_communicator();
}

}  // namespace desplat
