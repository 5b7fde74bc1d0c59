// The ordered sum's cost under a real launcher (docs/BENCHMARKS.md, ranks; the scaling model's
// bandwidth term): `mpirun -np N bench_comm_sum [MB]` sums a float array of MB megabytes
// (default 10, about a 40k-Gaussian model's gradient) 20 times and prints, on rank 0, the
// median seconds per sum and the payload rate (payload bytes / seconds). Not Google Benchmark:
// every rank must run the same calls, which a launcher starts, not the benchmark library.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "desplat/comm/communicator.hpp"
#include "desplat/core/stopwatch.hpp"

int main(int argc, char** argv) {
  auto comm = desplat::open_communicator(&argc, &argv);
  const double mb = argc > 1 ? std::atof(argv[1]) : 10.0;
  if (!(mb > 0 && mb <= 4096)) {
    std::fprintf(stderr, "bench_comm_sum: MB must be in (0, 4096], not %s\n", argv[1]);
    return 2;
  }
  std::vector<float> values(size_t(mb * 1024 * 1024 / sizeof(float)), 1.0f);
  std::vector<double> seconds;
  comm->sum(std::span(values));  // the first call sets up the transports
  for (int k = 0; k < 20; ++k) {
    comm->barrier();
    const desplat::Stopwatch watch;
    comm->sum(std::span(values));
    seconds.push_back(watch.seconds());
  }
  std::sort(seconds.begin(), seconds.end());
  const double median = seconds[seconds.size() / 2];
  if (comm->rank() == 0)
    std::printf("ranks %d (%s): sum of %.1f MB: median %.5f s, %.3f GB/s payload\n", comm->size(), comm->kind(), mb,
                median, mb / 1024.0 / median);
  return 0;
}
