// Deterministic random numbers for the generator: our own splitmix64 stream and Box–Muller
// normals, so the output is the same on every platform and standard library (the std
// distributions are implementation-defined) and for any thread count (each view, row or point
// draws from its own stream, keyed by what it is, never by which thread runs it).
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace desplat::synth {

inline uint64_t mix64(uint64_t x) {  // splitmix64's finalizer: a bijective avalanche
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Independent stream names, so e.g. the noise of view 3 never correlates with its distractors.
enum class Stream : uint64_t { Camera = 1, Distractors, Exposure, Noise, Jitter, Points, Clutter };

class Rng {
 public:
  Rng(uint64_t seed, Stream stream, uint64_t index = 0, uint64_t sub = 0)
      : state_(mix64(mix64(mix64(seed) ^ static_cast<uint64_t>(stream)) ^ index) ^ mix64(sub + 0x51ED)) {}

  uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ull); }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  int integer(int lo, int hi) {  // [lo, hi]
    return lo + static_cast<int>(next() % static_cast<uint64_t>(hi - lo + 1));
  }
  double normal() {                     // standard normal, Box–Muller
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2 * std::numbers::pi * u2);
  }

 private:
  uint64_t state_;
};

}  // namespace desplat::synth
