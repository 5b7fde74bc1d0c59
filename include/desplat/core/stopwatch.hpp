// Wall-clock timing for reports (seconds, steady clock). Never used to decide what to compute.
#pragma once

#include <chrono>

namespace desplat {

// Seconds since construction or the last restart(). Plain value; not shared between threads.
class Stopwatch {
 public:
  using Clock = std::chrono::steady_clock;
  Stopwatch() : start_(Clock::now()) {}
  double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  // Returns the seconds so far and starts again from now.
  double restart() {
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - start_).count();
    start_ = now;
    return s;
  }

 private:
  Clock::time_point start_;
};

}  // namespace desplat
