// A main() for the harnesses without libFuzzer: replays seed inputs and a bounded number of
// deterministic mutations of each through LLVMFuzzerTestOneInput, so the normal (gcc) build and
// ctest exercise the same entry functions the fuzzers do. A finding aborts, as under libFuzzer.
//
// Usage: replay <mutations per seed> <seed file or folder>...
// Mutations (fixed seed, so a failure replays): bit flips, byte insertions and deletions,
// chunk duplication, and runs of '[' / '{' (deep nesting), one to four per input.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void run(const std::string& input) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(input.data()), input.size());
}

std::string mutated(std::string s, std::mt19937& rng) {
  const int edits = 1 + int(rng() % 4);
  for (int e = 0; e < edits; ++e) {
    const std::size_t at = s.empty() ? 0 : rng() % (s.size() + 1);
    switch (rng() % 6) {
      case 0:
        if (!s.empty()) s[at % s.size()] ^= char(1u << (rng() % 8));
        break;
      case 1:
        s.insert(at, 1, char(rng() % 256));
        break;
      case 2:
        if (!s.empty()) s.erase(at % s.size(), 1 + rng() % 8);
        break;
      case 3:
        if (!s.empty()) {
          const std::size_t from = rng() % s.size();
          s.insert(at, s.substr(from, 1 + rng() % 32));
        }
        break;
      case 4:
        s.insert(at, std::string(1 + rng() % 2000, rng() % 2 ? '[' : '{'));
        break;
      default: {
        static const char* const tokens[] = {
            "-1",  "1e999",      "null", "\"\"", "[]", "{}", "true", "-9223372036854775809", "18446744073709551616",
            "0.5", "\"\\u0000\""};
        s.insert(at, tokens[rng() % (sizeof tokens / sizeof *tokens)]);
      }
    }
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s <mutations per seed> <seed file or folder>...\n", argv[0]);
    return 2;
  }
  const int mutations = std::atoi(argv[1]);
  std::vector<std::filesystem::path> seeds;
  for (int i = 2; i < argc; ++i) {
    const std::filesystem::path p = argv[i];
    if (std::filesystem::is_directory(p)) {
      for (const auto& e : std::filesystem::directory_iterator(p))
        if (e.is_regular_file()) seeds.push_back(e.path());
    } else {
      seeds.push_back(p);
    }
  }
  std::sort(seeds.begin(), seeds.end());
  if (seeds.empty()) {
    std::fprintf(stderr, "no seed inputs found\n");
    return 2;
  }
  std::mt19937 rng(20240601);
  std::size_t inputs = 0;
  for (const auto& seed : seeds) {
    const std::string base = read_file(seed);
    run(base), ++inputs;
    for (int m = 0; m < mutations; ++m) run(mutated(base, rng)), ++inputs;
  }
  std::printf("replayed %zu inputs from %zu seeds: no finding\n", inputs, seeds.size());
  return 0;
}
