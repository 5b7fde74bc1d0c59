// The one-process communicator: every collective over one rank is the identity.
#include <cstdio>
#include <cstdlib>

#include "desplat/comm/communicator.hpp"

namespace desplat {
namespace {

class SingleProcess final : public Communicator {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  void sum(std::span<float>) override {}
  void sum(std::span<double>) override {}
  void sum(std::span<int64_t>) override {}
  void broadcast(std::span<std::byte>, int root) override {
    if (root != 0) abort("broadcast from rank " + std::to_string(root) + " in a job of one rank");
  }
  void barrier() override {}
  [[noreturn]] void abort(const std::string& message) override {
    std::fprintf(stderr, "rank 0: %s\n", message.c_str());
    std::fflush(stderr);
    std::_Exit(1);
  }
  const char* kind() const override { return "single process"; }
};

}  // namespace

std::unique_ptr<Communicator> single_process_communicator() { return std::make_unique<SingleProcess>(); }

}  // namespace desplat
