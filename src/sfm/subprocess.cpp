// Child processes with merged output, a time limit and no leftovers (see subprocess.hpp).
#include "desplat/sfm/subprocess.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "desplat/core/stopwatch.hpp"

extern char** environ;

namespace desplat {
namespace fs = std::filesystem;
namespace {

constexpr double kGraceSeconds = 5;  // between SIGTERM and SIGKILL

// Kills and reaps the child if we leave early (an exception while handling its output).
class ChildGuard {
 public:
  explicit ChildGuard(pid_t pid) : pid_(pid) {}
  ChildGuard(const ChildGuard&) = delete;
  ChildGuard& operator=(const ChildGuard&) = delete;
  ~ChildGuard() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGKILL);
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
  }
  pid_t pid() const { return pid_; }
  // Blocks until the child ends (or, with a positive `limit`, at most that long); true when reaped.
  bool wait(ProcessExit& exit, double limit = 0) {
    const Stopwatch clock;
    for (;;) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, limit > 0 ? WNOHANG : 0);
      if (r < 0 && errno == EINTR) continue;
      if (r == 0) {  // still running (WNOHANG)
        if (clock.seconds() >= limit) return false;
        ::usleep(20000);
        continue;
      }
      pid_ = -1;
      if (r < 0)
        exit = {ProcessExit::How::Signaled, 0};
      else if (WIFSIGNALED(status))
        exit = {ProcessExit::How::Signaled, WTERMSIG(status)};
      else
        exit = {ProcessExit::How::Exited, WEXITSTATUS(status)};
      return true;
    }
  }

 private:
  pid_t pid_;
};

class Fd {
 public:
  explicit Fd(int fd = -1) : fd_(fd) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  int get() const { return fd_; }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_;
};

class SpawnActions {
 public:
  SpawnActions() { posix_spawn_file_actions_init(&fa_); }
  SpawnActions(const SpawnActions&) = delete;
  SpawnActions& operator=(const SpawnActions&) = delete;
  ~SpawnActions() { posix_spawn_file_actions_destroy(&fa_); }
  posix_spawn_file_actions_t* get() { return &fa_; }

 private:
  posix_spawn_file_actions_t fa_;
};

class SpawnAttr {
 public:
  // Default signal dispositions and an empty mask (an ignored SIGPIPE or SIGINT would
  // otherwise be inherited by the child).
  SpawnAttr() {
    posix_spawnattr_init(&attr_);
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    for (int sig : {SIGPIPE, SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaddset(&defaults, sig);
    posix_spawnattr_setsigmask(&attr_, &none);
    posix_spawnattr_setsigdefault(&attr_, &defaults);
    posix_spawnattr_setflags(&attr_, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  }
  SpawnAttr(const SpawnAttr&) = delete;
  SpawnAttr& operator=(const SpawnAttr&) = delete;
  ~SpawnAttr() { posix_spawnattr_destroy(&attr_); }
  const posix_spawnattr_t* get() const { return &attr_; }

 private:
  posix_spawnattr_t attr_;
};

}  // namespace

ProcessExit run_subprocess(const std::vector<std::string>& argv, const std::function<void(std::string_view)>& on_output,
                           double time_limit_seconds) {
  if (argv.empty()) throw std::invalid_argument("run_subprocess: no program given");
  if (!(time_limit_seconds >= 0))
    throw std::invalid_argument("time limit must be 0 (none) or positive, got " + std::to_string(time_limit_seconds));
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw SubprocessError(std::string("cannot create a pipe: ") + std::strerror(errno));
  Fd read_end(fds[0]), write_end(fds[1]);
  SpawnActions actions;
  posix_spawn_file_actions_addopen(actions.get(), 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(actions.get(), write_end.get(), 1);
  posix_spawn_file_actions_adddup2(actions.get(), write_end.get(), 2);
  std::vector<char*> cargv;
  for (const std::string& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  pid_t pid = 0;
  const SpawnAttr attr;
  const int err = ::posix_spawn(&pid, cargv[0], actions.get(), attr.get(), cargv.data(), environ);
  if (err != 0) throw SubprocessError("cannot start '" + argv[0] + "': " + std::strerror(err));
  ChildGuard child(pid);
  write_end.reset();  // EOF arrives once the child (and anything it started) closes the pipe

  const Stopwatch clock;
  bool timed_out = false;
  char buf[1 << 16];
  for (;;) {
    int wait_ms = -1;
    if (time_limit_seconds > 0) {
      const double left = time_limit_seconds - clock.seconds();
      if (left <= 0) {
        timed_out = true;
        break;
      }
      wait_ms = int(std::min(left * 1000.0 + 1.0, 1000.0));
    }
    pollfd p{read_end.get(), POLLIN, 0};
    const int ready = ::poll(&p, 1, wait_ms);
    if (ready < 0 && errno == EINTR) continue;
    if (ready == 0) continue;  // no output yet: look at the clock again
    const ssize_t n = ::read(read_end.get(), buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    on_output(std::string_view(buf, static_cast<size_t>(n)));
  }
  ProcessExit exit;
  if (!timed_out) {
    child.wait(exit);
    return exit;
  }
  ::kill(child.pid(), SIGTERM);
  if (!child.wait(exit, kGraceSeconds)) {
    ::kill(child.pid(), SIGKILL);
    child.wait(exit);
  }
  return {ProcessExit::How::TimedOut, 0};
}

std::optional<fs::path> find_executable(const std::string& name) {
  if (name.empty()) return std::nullopt;
  const auto usable = [](const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
  };
  if (name.find('/') != std::string::npos) {
    if (usable(name)) return fs::absolute(name);
    return std::nullopt;
  }
  const char* path_env = std::getenv("PATH");
  std::string_view rest = path_env ? path_env : "";
  while (path_env) {
    const size_t colon = rest.find(':');
    const std::string_view dir = rest.substr(0, colon);
    const fs::path candidate = fs::path(dir.empty() ? "." : std::string(dir)) / name;  // POSIX: empty = cwd
    if (usable(candidate)) return fs::absolute(candidate);
    if (colon == std::string_view::npos) break;
    rest.remove_prefix(colon + 1);
  }
  return std::nullopt;
}

}  // namespace desplat
