// The one-process communicator (desplat/comm/communicator.hpp): a job of one rank, whose sums
// and broadcasts leave the values as they are, and whose abort ends the process with its
// message; and how a launch is read (read_launch_environment). The MPI communicator's checks run
// under mpirun (tests/comm_mpi_check.cpp).
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "desplat/comm/communicator.hpp"

namespace desplat::test {
namespace {

TEST(SingleProcessCommunicator, IsOneRank) {
  const auto comm = single_process_communicator();
  EXPECT_EQ(comm->rank(), 0);
  EXPECT_EQ(comm->size(), 1);
  EXPECT_STREQ(comm->kind(), "single process");
}

TEST(SingleProcessCommunicator, SumOverOneRankKeepsEveryBit) {
  const auto comm = single_process_communicator();
  std::vector<float> f = {1.5f, -0.0f, std::numeric_limits<float>::denorm_min(), 3.4e38f};
  const std::vector<float> f0 = f;
  comm->sum(f);
  EXPECT_EQ(std::memcmp(f.data(), f0.data(), f.size() * sizeof(float)), 0);  // −0 stays −0
  std::vector<double> d = {1e300, -2.5};
  comm->sum(d);
  EXPECT_EQ(d, (std::vector<double>{1e300, -2.5}));
  std::vector<int64_t> i = {std::numeric_limits<int64_t>::max(), -7};
  comm->sum(i);
  EXPECT_EQ(i, (std::vector<int64_t>{std::numeric_limits<int64_t>::max(), -7}));
}

TEST(SingleProcessCommunicator, BroadcastFromItselfAndBarrierReturn) {
  const auto comm = single_process_communicator();
  std::vector<std::byte> bytes = {std::byte{1}, std::byte{2}, std::byte{255}};
  comm->broadcast(bytes, 0);
  EXPECT_EQ(bytes, (std::vector<std::byte>{std::byte{1}, std::byte{2}, std::byte{255}}));
  comm->barrier();
}

TEST(SingleProcessCommunicatorDeathTest, AbortEndsTheProcessNamingTheRank) {
  EXPECT_EXIT(single_process_communicator()->abort("cannot read photo x.jpg"), testing::ExitedWithCode(1),
              "rank 0: cannot read photo x.jpg");
  // A broadcast from a rank the job does not have is an abort too, never a silent no-op.
  std::vector<std::byte> b(4);
  EXPECT_EXIT(single_process_communicator()->broadcast(b, 1), testing::ExitedWithCode(1),
              "rank 0: broadcast from rank 1");
}

TEST(OpenCommunicator, WithoutALauncherIsOneProcess) {
  // ctest starts this test directly: no launcher's environment, so no MPI initialization.
  int argc = 0;
  char** argv = nullptr;
  const auto comm = open_communicator(&argc, &argv);
  EXPECT_EQ(comm->size(), 1);
  EXPECT_STREQ(comm->kind(), "single process");
}

// An environment as a table, for read_launch_environment.
LaunchEnvironment launched_with(const std::map<std::string, std::string>& vars, bool with_mpi) {
  return read_launch_environment(
      [&](const char* name) -> const char* {
        const auto it = vars.find(name);
        return it == vars.end() ? nullptr : it->second.c_str();
      },
      with_mpi);
}

// The variables each launcher sets, as srun (Slurm 22.05), sbatch and Open MPI 4.1's mpirun set
// them on Debian 12 (scripts/checks/srun.sh's cluster).
TEST(LaunchEnvironment, EachLauncherIsReadForWhatItStarted) {
  // A plain start, and an sbatch script (SLURM_PROCID without a job step): one process.
  EXPECT_FALSE(launched_with({}, true).mpi);
  EXPECT_EQ(launched_with({}, true).tasks, 1);
  const LaunchEnvironment batch = launched_with({{"SLURM_PROCID", "0"}, {"SLURM_NTASKS", "2"}}, true);
  EXPECT_FALSE(batch.mpi);
  EXPECT_EQ(batch.tasks, 1);
  EXPECT_EQ(batch.error, "");
  // srun with one task and no MPI plugin: one process, MPI never initialized.
  const LaunchEnvironment one =
      launched_with({{"SLURM_PROCID", "0"}, {"SLURM_STEP_ID", "0"}, {"SLURM_STEP_NUM_TASKS", "1"}}, true);
  EXPECT_FALSE(one.mpi);
  EXPECT_EQ(one.error, "");
  // srun --mpi=pmix with two tasks, and mpirun -np 3: MPI.
  const LaunchEnvironment pmix = launched_with(
      {{"SLURM_PROCID", "1"}, {"SLURM_STEP_NUM_TASKS", "2"}, {"PMIX_RANK", "1"}, {"SLURM_NTASKS", "2"}}, true);
  EXPECT_TRUE(pmix.mpi);
  EXPECT_EQ(pmix.tasks, 2);
  EXPECT_EQ(pmix.error, "");
  const LaunchEnvironment mpirun = launched_with({{"OMPI_COMM_WORLD_SIZE", "3"}, {"PMIX_RANK", "0"}}, true);
  EXPECT_TRUE(mpirun.mpi);
  EXPECT_EQ(mpirun.tasks, 3);
}

TEST(LaunchEnvironment, ALaunchThatCannotRunSaysWhatToDo) {
  // srun's two tasks without --mpi=pmix: MPI_Init would fail in each; say how to start it.
  const LaunchEnvironment srun = launched_with({{"SLURM_PROCID", "0"}, {"SLURM_STEP_NUM_TASKS", "2"}}, true);
  EXPECT_EQ(srun.error,
            "started by srun as 2 tasks without an MPI plugin that Open MPI can join; run srun --mpi=pmix (or set "
            "MpiDefault=pmix in slurm.conf)");
  // Two processes of a build without MPI would each train alone into one output folder.
  for (const auto& vars : std::vector<std::map<std::string, std::string>>{
           {{"OMPI_COMM_WORLD_SIZE", "2"}, {"PMIX_RANK", "0"}}, {{"SLURM_STEP_NUM_TASKS", "4"}, {"PMIX_RANK", "3"}}}) {
    const LaunchEnvironment e = launched_with(vars, false);
    EXPECT_NE(e.error.find("this build has no MPI, so each would train alone into the same output folder"),
              std::string::npos)
        << e.error;
  }
  // One process of that build under mpirun -np 1 is fine; a count that is not one is ignored.
  EXPECT_EQ(launched_with({{"OMPI_COMM_WORLD_SIZE", "1"}}, false).error, "");
  EXPECT_EQ(launched_with({{"SLURM_STEP_NUM_TASKS", "two"}}, true).tasks, 1);
}

}  // namespace
}  // namespace desplat::test
