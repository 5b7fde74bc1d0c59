// The MPI communicator: MPI moves the bytes, our code does every sum (communicator.hpp).
#include "comm/mpi_communicator.hpp"

#include <mpi.h>

#include <algorithm>
#include <climits>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include "desplat/core/stopwatch.hpp"

namespace desplat {
namespace {

template <typename T>
MPI_Datatype mpi_type();
template <>
MPI_Datatype mpi_type<float>() {
  return MPI_FLOAT;
}
template <>
MPI_Datatype mpi_type<double>() {
  return MPI_DOUBLE;
}
template <>
MPI_Datatype mpi_type<int64_t>() {
  return MPI_INT64_T;
}

// Values per chunk of the ordered sum: rank 0 holds size() chunks at a time, so its extra
// memory stays bounded whatever the array's length (and MPI counts stay within int).
constexpr size_t kChunkValues = size_t(1) << 20;

class Mpi final : public Communicator {
 public:
  Mpi(int* argc, char*** argv) {
    int provided = 0;
    if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
      throw std::runtime_error("MPI_Init_thread failed");
    if (provided < MPI_THREAD_FUNNELED) {
      MPI_Finalize();
      throw std::runtime_error("this MPI library does not support threads inside a rank (MPI_THREAD_FUNNELED)");
    }
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  ~Mpi() override { MPI_Finalize(); }
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  void sum(std::span<float> v) override {
    metered(v.size_bytes(), [&] { ordered_sum(v); });
  }
  void sum(std::span<double> v) override {
    metered(v.size_bytes(), [&] { ordered_sum(v); });
  }
  void sum(std::span<int64_t> v) override {
    metered(v.size_bytes(), [&] { ordered_sum(v); });
  }
  void broadcast(std::span<std::byte> bytes, int root) override {
    if (root < 0 || root >= size_)
      abort("broadcast from rank " + std::to_string(root) + " of " + std::to_string(size_));
    metered(bytes.size(), [&] {
      for (size_t at = 0; at < bytes.size(); at += size_t(INT_MAX)) {
        const int n = int(std::min(bytes.size() - at, size_t(INT_MAX)));
        check(MPI_Bcast(bytes.data() + at, n, MPI_BYTE, root, MPI_COMM_WORLD), "MPI_Bcast");
      }
    });
  }
  void barrier() override {
    metered(0, [&] { check(MPI_Barrier(MPI_COMM_WORLD), "MPI_Barrier"); });
  }
  [[noreturn]] void abort(const std::string& message) override {
    std::fprintf(stderr, "rank %d: %s\n", rank_, message.c_str());
    std::fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
    std::_Exit(1);  // MPI_Abort does not return; this keeps the contract if it did
  }
  const char* kind() const override { return "MPI"; }

 private:
  int rank_ = 0, size_ = 1;
  std::vector<std::byte> gathered_;  // rank 0: one chunk from every rank

  template <class Fn>
  void metered(size_t bytes, Fn&& fn) {
    const Stopwatch watch;
    fn();
    totals_.seconds += watch.seconds();
    totals_.bytes += int64_t(bytes);
    ++totals_.calls;
  }

  void check(int code, const char* call) {
    if (code == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    abort(std::string(call) + " failed: " + std::string(text, size_t(length)));
  }

  // Chunk by chunk: gather every rank's values to rank 0, add them there in the rank tree's
  // order (communicator.hpp), broadcast the sums.
  template <typename T>
  void ordered_sum(std::span<T> values) {
    if (size_ == 1) return;
    for (size_t at = 0; at < values.size(); at += kChunkValues) {
      const size_t n = std::min(values.size() - at, kChunkValues);
      T* chunk = values.data() + at;
      if (rank_ == 0) gathered_.resize(n * sizeof(T) * size_t(size_));
      check(MPI_Gather(chunk, int(n), mpi_type<T>(), rank_ == 0 ? gathered_.data() : nullptr, int(n), mpi_type<T>(), 0,
                       MPI_COMM_WORLD),
            "MPI_Gather");
      if (rank_ == 0) {
        // Bottom-up: row o holds S(o, s) after the pass of stride s, from the widest stride
        // below the rank count down to 1, where row 0 holds S(0, 1).
        T* all = reinterpret_cast<T*>(gathered_.data());
        int widest = 1;
        while (2 * widest < size_) widest *= 2;
        for (int s = widest; s >= 1; s /= 2)
          for (int o = 0; o < s && o + s < size_; ++o) {
            T* into = all + size_t(o) * n;
            const T* from = all + size_t(o + s) * n;
            for (size_t i = 0; i < n; ++i) into[i] += from[i];
          }
        std::copy_n(all, n, chunk);
      }
      check(MPI_Bcast(chunk, int(n), mpi_type<T>(), 0, MPI_COMM_WORLD), "MPI_Bcast");
    }
  }
};

}  // namespace

std::unique_ptr<Communicator> mpi_communicator(int* argc, char*** argv) { return std::make_unique<Mpi>(argc, argv); }

}  // namespace desplat
