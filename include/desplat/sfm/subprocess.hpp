// Running an external program (COLMAP) the way a long job needs: no shell, stdin from
// /dev/null, stdout and stderr merged into one stream handed to the caller as it arrives, a
// time limit after which the program is stopped, and a child never left behind (it is killed
// and reaped when the caller's callback throws).
//
// Thread safety: one call runs one child; concurrent calls are independent. Needs SIGCHLD not
// to be ignored (to read the exit status). The child gets default signal dispositions and an
// empty signal mask, whatever the caller ignores or blocks.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace desplat {

struct SubprocessError : std::runtime_error {  // the program could not be started at all
  using std::runtime_error::runtime_error;
};

struct ProcessExit {
  enum class How { Exited, Signaled, TimedOut };
  How how = How::Exited;
  int code = 0;  // exit status (Exited) or signal number (Signaled); 0 for TimedOut
  bool ok() const { return how == How::Exited && code == 0; }
};

// Runs argv[0] (a path to an executable; see find_executable) with argv[1…], calling
// `on_output` with each chunk of its output. `time_limit_seconds` > 0: past it the program gets
// SIGTERM, then SIGKILL 5 s later if it is still there, and the result is TimedOut; 0 means no
// limit; negative is an error (std::invalid_argument). Throws SubprocessError when argv[0]
// cannot be started (missing, not executable), naming it.
ProcessExit run_subprocess(const std::vector<std::string>& argv, const std::function<void(std::string_view)>& on_output,
                           double time_limit_seconds);

// Absolute path of `name` (searched on PATH unless it contains '/'), if it is an executable file.
std::optional<std::filesystem::path> find_executable(const std::string& name);

}  // namespace desplat
