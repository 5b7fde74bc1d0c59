// The one-process communicator (desplat/comm/communicator.hpp): a job of one rank, whose sums
// and broadcasts leave the values as they are, and whose abort ends the process with its
// message. The MPI communicator's checks run under mpirun (tests/comm_mpi_check.cpp).
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
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

}  // namespace
}  // namespace desplat::test
