// The MPI communicator (built only with DESPLAT_WITH_MPI; communicator.hpp's contracts).
#pragma once

#include <memory>

#include "desplat/comm/communicator.hpp"

namespace desplat {

#if DESPLAT_WITH_MPI
// Initializes MPI (MPI_THREAD_FUNNELED) over MPI_COMM_WORLD; finalizes it on destruction.
// Throws std::runtime_error when MPI cannot be initialized or gives fewer threads support.
std::unique_ptr<Communicator> mpi_communicator(int* argc, char*** argv);
#endif

}  // namespace desplat
