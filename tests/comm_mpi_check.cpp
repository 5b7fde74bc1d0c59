// The MPI communicator against known answers, run by ctest under `mpirun -np 2` and `-np 4` (and
// with any rank count by hand). Modes:
//   collectives  sum (float, double, int64), broadcast and barrier against answers each rank
//                computes itself; exits 0 when every check passes on every rank.
//   abort        the last rank aborts while the others wait in a barrier that would never
//                return: the job must end (ctest's TIMEOUT bounds it) with that rank's message.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "desplat/comm/communicator.hpp"

namespace {

int failures = 0;
void expect(bool ok, const std::string& what, int rank) {
  if (ok) return;
  std::fprintf(stderr, "rank %d: FAILED %s\n", rank, what.c_str());
  ++failures;
}

// Rank r's values: chosen so that the order of the float additions changes the result
// (1e8 + 1 + … loses the ones that a different association would keep).
float float_value(int r, size_t i) { return r == 0 ? 1e8f : 1.0f + float(i % 7) * 0.25f + float(r); }

// The rank tree's sum (communicator.hpp) by its recursive definition: S(o, s) = S(o, 2s) +
// S(o + s, 2s) over the ranks o, o + s, o + 2s, … below `size`.
template <typename T, typename Value>
T tree_sum(const Value& x, int size, int o = 0, int s = 1) {
  if (o + s >= size) return x(o);
  return tree_sum<T>(x, size, o, 2 * s) + tree_sum<T>(x, size, o + s, 2 * s);
}

int collectives(desplat::Communicator& comm) {
  const int rank = comm.rank(), size = comm.size();
  // Longer than one chunk of the ordered sum, so the chunking is covered.
  const size_t n = (size_t(1) << 20) + 1000;
  std::vector<float> f(n);
  for (size_t i = 0; i < n; ++i) f[i] = float_value(rank, i);
  comm.sum(f);
  size_t wrong = 0;
  for (size_t i = 0; i < n; ++i) {
    const float expected = tree_sum<float>([&](int r) { return float_value(r, i); }, size);
    wrong += std::memcmp(&f[i], &expected, sizeof(float)) != 0;
  }
  expect(wrong == 0, "float sum: " + std::to_string(wrong) + " values differ from the rank tree's sum", rank);
  // Rerun: the same bits.
  std::vector<float> again(n);
  for (size_t i = 0; i < n; ++i) again[i] = float_value(rank, i);
  comm.sum(again);
  expect(std::memcmp(again.data(), f.data(), n * sizeof(float)) == 0, "float sum: a rerun gave other bits", rank);

  std::vector<double> d = {double(rank) + 0.5, -1e300 * (rank == 0), 1.0 / (rank + 1)};
  comm.sum(d);
  const double harmonic = tree_sum<double>([](int r) { return 1.0 / (r + 1); }, size);
  expect(d[0] == double(size) * (size - 1) / 2 + 0.5 * size, "double sum of r + 0.5", rank);
  expect(d[1] == -1e300, "double sum with one nonzero term", rank);
  expect(d[2] == harmonic, "double sum of 1/(r+1)", rank);

  // Beyond 2^53: an int64 sum must stay exact (a sum through double would not).
  std::vector<int64_t> k = {(int64_t(1) << 60) + rank, -int64_t(rank)};
  comm.sum(k);
  expect(k[0] == int64_t(size) * (int64_t(1) << 60) + int64_t(size) * (size - 1) / 2, "int64 sum beyond 2^53", rank);
  expect(k[1] == -int64_t(size) * (size - 1) / 2, "int64 sum of −r", rank);

  // Broadcast from the last rank: every rank ends with its bytes.
  const int root = size - 1;
  std::vector<std::byte> bytes(1000);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = std::byte(rank == root ? (i * 7 + 3) % 256 : 0);
  comm.broadcast(bytes, root);
  bool same = true;
  for (size_t i = 0; i < bytes.size(); ++i) same = same && bytes[i] == std::byte((i * 7 + 3) % 256);
  expect(same, "broadcast from rank " + std::to_string(root), rank);

  comm.barrier();
  // Every rank's failure count, summed: all ranks agree whether the job passed.
  std::vector<int64_t> failed = {failures};
  comm.sum(failed);
  if (rank == 0) std::printf("%d ranks (%s): %s\n", size, comm.kind(), failed[0] == 0 ? "all checks passed" : "FAILED");
  return failed[0] == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  auto comm = desplat::open_communicator(&argc, &argv);
  if (comm->size() < 2) {
    std::fprintf(stderr, "comm_mpi_check: start it with mpirun -np 2 or more (got %d rank, %s)\n", comm->size(),
                 comm->kind());
    return 2;
  }
  if (mode == "collectives") return collectives(*comm);
  if (mode == "abort") {
    if (comm->rank() == comm->size() - 1) comm->abort("deliberate abort while the other ranks wait");
    comm->barrier();  // never returns: the aborting rank never arrives
    std::fprintf(stderr, "rank %d: the barrier returned without the aborted rank\n", comm->rank());
    return 1;
  }
  std::fprintf(stderr, "comm_mpi_check: mode must be collectives or abort\n");
  return 2;
}
