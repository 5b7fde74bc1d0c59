// Ctrl-C and SIGTERM as a stop request that long jobs poll between steps, so they can save
// their work (a checkpoint, a CSV) before exiting. Shared by the apps; not part of the library.
#pragma once

#include <atomic>
#include <csignal>

namespace desplat_apps {

inline std::atomic<bool> stop_requested{false};

// Installs the handlers; returns the flag they set.
inline const std::atomic<bool>& stop_on_signals() {
  auto on_signal = [](int) { stop_requested.store(true); };
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  return stop_requested;
}

}  // namespace desplat_apps
