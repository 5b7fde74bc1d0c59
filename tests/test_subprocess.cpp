// The subprocess helper behind the SfM stages: a missing program, a failing one (exit code and
// output), a hung one stopped at its time limit and reaped, and output that arrives as written.
// Expectations come from what the shell commands do by definition.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cerrno>
#include <string>

#include "desplat/sfm/subprocess.hpp"
#include "support/expect.hpp"
#include "support/scoped_env.hpp"
#include "support/temp_dir.hpp"

namespace desplat {
namespace {
namespace fs = std::filesystem;
using testing::ScopedEnv;
using testing::spit;
using testing::TempDir;

std::string sh() { return find_executable("sh").value().string(); }

TEST(Subprocess, MissingProgramIsOneClearError) {
  EXPECT_CONTAINS(testing::error_of<SubprocessError>([] {
                    run_subprocess(
                        {"/nonexistent/colmap", "mapper"}, [](std::string_view) {}, 0);
                  }),
                  "cannot start '/nonexistent/colmap'");
  EXPECT_EQ(find_executable("no-such-program-anywhere"), std::nullopt);
}

TEST(Subprocess, ExitCodeAndMergedOutputAreReported) {
  std::string output;
  const ProcessExit exit = run_subprocess(
      {sh(), "-c", "echo out; echo err 1>&2; exit 3"}, [&](std::string_view s) { output += s; }, 0);
  EXPECT_EQ(exit.how, ProcessExit::How::Exited);
  EXPECT_EQ(exit.code, 3);
  EXPECT_FALSE(exit.ok());
  EXPECT_EQ(output, "out\nerr\n");
}

TEST(Subprocess, SignalIsReported) {
  const ProcessExit exit = run_subprocess(
      {sh(), "-c", "kill -9 $$"}, [](std::string_view) {}, 0);
  EXPECT_EQ(exit.how, ProcessExit::How::Signaled);
  EXPECT_EQ(exit.code, 9);
}

TEST(Subprocess, HungProgramIsStoppedAtItsTimeLimitAndReaped) {
  std::string output;
  // Prints its pid, then sleeps far past the limit (exec: the shell becomes sleep, same pid).
  const ProcessExit exit = run_subprocess(
      {sh(), "-c", "echo $$; exec sleep 60"}, [&](std::string_view s) { output += s; }, 0.5);
  EXPECT_EQ(exit.how, ProcessExit::How::TimedOut);
  const pid_t pid = std::stoi(output);
  // Reaped: the pid is no child of ours any more, and no process has it.
  EXPECT_EQ(::waitpid(pid, nullptr, WNOHANG), -1);
  EXPECT_EQ(errno, ECHILD);
  EXPECT_EQ(::kill(pid, 0), -1);
}

TEST(Subprocess, ProgramIgnoringTermIsKilled) {
  std::string output;
  const ProcessExit exit = run_subprocess(
      {sh(), "-c", "trap '' TERM; echo $$; while :; do sleep 1; done"}, [&](std::string_view s) { output += s; }, 0.3);
  EXPECT_EQ(exit.how, ProcessExit::How::TimedOut);
  EXPECT_EQ(::kill(std::stoi(output), 0), -1);
}

TEST(Subprocess, FindExecutableSearchesPathForExecutableFiles) {
  TempDir tmp;
  spit(tmp.path() / "tool", "#!/bin/sh\n");
  spit(tmp.path() / "data", "x");
  fs::permissions(tmp.path() / "tool", fs::perms::owner_all);
  ScopedEnv path("PATH", "/nonexistent:" + tmp.path().string());
  EXPECT_EQ(find_executable("tool"), tmp.path() / "tool");
  EXPECT_EQ(find_executable("data"), std::nullopt);  // not executable
  EXPECT_EQ(find_executable((tmp.path() / "tool").string()), tmp.path() / "tool");
  EXPECT_EQ(find_executable("missing"), std::nullopt);
}

TEST(Subprocess, ANegativeTimeLimitIsRefused) {
  EXPECT_THROW(run_subprocess(
                   {sh(), "-c", "true"}, [](std::string_view) {}, -1),
               std::invalid_argument);
}

}  // namespace
}  // namespace desplat
