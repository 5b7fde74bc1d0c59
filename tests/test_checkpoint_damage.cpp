// Checkpoints that were damaged (corrupted or truncated bytes, flipped bits, absurd sizes) or
// whose writer died mid-write: every damage is reported naming the file and the section, and a
// crashed writer always leaves the previous checkpoint readable.
#include <gtest/gtest.h>

#include "support/checkpoint_fixtures.hpp"

namespace desplat {
namespace {
using namespace checkpoint_test;

// ---------------------------------------------------------------------------
// Corruption: each kind gives one clear error naming the file.

TEST_F(CheckpointCorruption, FileLevelProblems) {
  EXPECT_THAT(read_error(file("missing.ckpt")), HasSubstr("file does not exist"));
  EXPECT_THAT(read_error(dir_), HasSubstr("not a regular file"));

  write_bytes(file("empty.ckpt"), "");
  EXPECT_THAT(read_error(file("empty.ckpt")), HasSubstr("truncated: 0 bytes, shorter than the 24-byte file header"));

  RawFile f = raw_valid();
  f.magic = "PK\x03\x04zip!";
  write_bytes(file("magic.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("magic.ckpt")), HasSubstr("not a desplat checkpoint (bad magic number)"));

  f = raw_valid();
  f.version = 2;
  write_bytes(file("version.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("version.ckpt")),
              HasSubstr("unsupported checkpoint format version 2 (this build reads version 1)"));

  f = raw_valid();
  f.reserved = 1;
  write_bytes(file("reserved.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("reserved.ckpt")), HasSubstr("reserved file header field is not 0"));

  std::string flipped = raw_valid().bytes();
  flipped[12] ^= 0x04;  // section count
  write_bytes(file("hdrcrc.ckpt"), flipped);
  EXPECT_THAT(read_error(file("hdrcrc.ckpt")), HasSubstr("file header checksum mismatch"));

  write_bytes(file("trailing.ckpt"), raw_valid().bytes() + "x");
  EXPECT_THAT(read_error(file("trailing.ckpt")), HasSubstr("1 trailing bytes after the last of 3 sections"));

  f = raw_valid();
  f.section_count = 0;
  write_bytes(file("zero.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("zero.ckpt")), HasSubstr("no sections"));
}

TEST_F(CheckpointCorruption, AbsurdCountsAndSizesAreRejectedBeforeAllocating) {
  RawFile f = raw_valid();
  f.section_count = 0xffffffffu;  // with a valid header checksum
  write_bytes(file("count.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("count.ckpt")), HasSubstr("header declares 4294967295 sections, but the"));

  // 2^60 bytes of float32: a consistent shape, checksummed header, no payload behind it.
  // Allocating first would throw std::bad_alloc, which fails this test.
  f = raw_valid();
  f.sections[1] = {1, "huge", {std::uint64_t{1} << 58}, std::uint64_t{1} << 60, ""};
  write_bytes(file("huge.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("huge.ckpt")),
              HasSubstr("truncated: section 'huge' declares 1152921504606846976 payload bytes"));

  f.sections[1] = {1, "overflow", {std::uint64_t{1} << 40, std::uint64_t{1} << 40}, 0, ""};
  write_bytes(file("overflow.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("overflow.ckpt")),
              HasSubstr("section 'overflow': shape [1099511627776, 1099511627776] is too large"));

  f = raw_valid();
  f.sections[0].payload_size = std::uint64_t{1} << 62;
  f.sections[0].dims = {std::uint64_t{1} << 62};
  write_bytes(file("meta.ckpt"), f.bytes());
  EXPECT_THAT(read_error(file("meta.ckpt")), HasSubstr("truncated: section 'metadata' declares"));
}

TEST_F(CheckpointCorruption, SectionHeaderProblems) {
  const auto error_for = [&](const std::string& name, const RawFile& f) {
    write_bytes(file(name), f.bytes());
    return read_error(file(name));
  };
  RawFile f = raw_valid();
  f.sections[1].payload_size = 28;  // [2, 3] float32 is 24 bytes
  f.sections[1].payload += "pad!";
  EXPECT_THAT(error_for("size.ckpt", f), HasSubstr("section 'a': shape [2, 3] of 4-byte elements needs 24 bytes, "
                                                   "but the section declares 28"));

  f = raw_valid();
  f.sections[2].type = 9;
  EXPECT_THAT(error_for("type.ckpt", f), HasSubstr("section 'b': unknown element type 9"));
  f.sections[2].type = 0;
  EXPECT_THAT(error_for("meta2.ckpt", f), HasSubstr("(a second metadata section)"));

  f = raw_valid();
  f.sections[1].dims = std::vector<std::uint64_t>(9, 1);
  EXPECT_THAT(error_for("rank.ckpt", f), HasSubstr("section #1 (offset 70): rank 9 exceeds 8"));

  f = raw_valid();
  f.sections[1].name = "";
  EXPECT_THAT(error_for("noname.ckpt", f), HasSubstr("section #1 (offset 70): name length 0 is not in 1..255"));
  f.sections[1].name = "a b";
  EXPECT_THAT(error_for("space.ckpt", f), HasSubstr("invalid section name"));
  f.sections[1].name = "b";
  EXPECT_THAT(error_for("dup.ckpt", f), HasSubstr("duplicate array 'b'"));

  std::string flipped = raw_valid().bytes();
  flipped[70 + 13] ^= 0x10;  // a dims byte of section #1
  write_bytes(file("hcrc.ckpt"), flipped);
  EXPECT_THAT(read_error(file("hcrc.ckpt")), HasSubstr("section #1 (offset 70): header checksum mismatch (stored 0x"));
}

TEST_F(CheckpointCorruption, MetadataProblems) {
  const auto error_for = [&](const std::string& name, const RawFile& f) {
    write_bytes(file(name), f.bytes());
    return read_error(file(name));
  };
  RawFile f = raw_valid();
  f.sections.erase(f.sections.begin());
  EXPECT_THAT(error_for("nometa.ckpt", f), HasSubstr("the first section must be the metadata, found 'a' of type 1"));
  f = raw_valid();
  f.sections[0] = raw_metadata("{\"step\": ");
  EXPECT_THAT(error_for("json.ckpt", f), HasSubstr("metadata is not valid JSON"));
  f.sections[0] = raw_metadata("[1, 2]");
  EXPECT_THAT(error_for("array.ckpt", f), HasSubstr("metadata is a JSON array, expected an object"));
  f.sections[0] = raw_metadata("{}");
  f.sections[0].dims = {2, 1};
  EXPECT_THAT(error_for("rank.ckpt", f), HasSubstr("metadata section has rank 2, expected 1"));
}

TEST_F(CheckpointCorruption, PayloadChecksumMismatchNamesTheSection) {
  const fs::path path = file("c.ckpt");
  Checkpoint c = small_checkpoint();
  write_checkpoint(path, c);
  std::string bytes = read_bytes(path);
  // Find the payload of "static/means" the way a reader of the spec would: via our encoder.
  RawFile raw;
  raw.sections.push_back(raw_metadata(c.metadata.dump()));
  std::size_t index = 0;
  for (const auto& [name, a] : c.arrays) {
    if (name == "static/means") index = raw.sections.size();
    std::string payload(a.byte_size(), '\0');
    if (!payload.empty()) std::memcpy(payload.data(), a.data(), payload.size());
    raw.sections.push_back({static_cast<std::uint8_t>(a.type()), name, a.shape(), payload.size(), payload});
  }
  std::vector<std::size_t> offsets;
  ASSERT_EQ(raw.bytes(&offsets), bytes);
  bytes[offsets[index] + 5] ^= 0x01;  // one bit of one float
  write_bytes(path, bytes);
  EXPECT_THAT(read_error(path), AllOf(HasSubstr("checksum mismatch in section 'static/means' (stored 0x"),
                                      HasSubstr("the data is corrupt")));
}

TEST_F(CheckpointCorruption, EveryTruncationIsReported) {
  const fs::path good = file("good.ckpt"), cut = file("cut.ckpt");
  write_checkpoint(good, small_checkpoint());
  const std::string bytes = read_bytes(good);
  for (std::size_t len = 0; len < bytes.size(); ++len) {
    write_bytes(cut, bytes.substr(0, len));
    ASSERT_THAT(read_error(cut), HasSubstr("truncated")) << "prefix of " << len << " of " << bytes.size() << " bytes";
  }
}

TEST_F(CheckpointCorruption, EverySingleBitFlipIsDetected) {
  const fs::path good = file("good.ckpt"), bad = file("bad.ckpt");
  write_checkpoint(good, small_checkpoint());
  const std::string bytes = read_bytes(good);
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    std::string flipped = bytes;
    flipped[i] = static_cast<char>(flipped[i] ^ (1 << (i % 8)));
    write_bytes(bad, flipped);
    ASSERT_THAT(read_error(bad), Not(HasSubstr("(no exception)"))) << "bit " << i % 8 << " of byte " << i;
  }
}

// ---------------------------------------------------------------------------
// Crashes: the previous checkpoint survives a writer that dies or fails mid-write.

// Runs write_checkpoint(path, c) in a child process after `setup`; returns its pid.
// The child never returns into the test: it _exits 0 on success, 3 on an exception.
pid_t spawn_writer(const fs::path& path, const Checkpoint& c, const std::function<void()>& setup) {
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  const rlimit no_core{0, 0};
  ::setrlimit(RLIMIT_CORE, &no_core);
  setup();
  try {
    write_checkpoint(path, c);
  } catch (...) {
    ::_exit(3);
  }
  ::_exit(0);
}

int wait_for(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return status;
}

std::optional<std::uintmax_t> size_of(const fs::path& p) {
  struct stat sb {};
  if (::stat(p.c_str(), &sb) != 0) return std::nullopt;
  return static_cast<std::uintmax_t>(sb.st_size);
}

// Fixture state shared by the crash tests: an existing ~4 MB checkpoint and a ~50 MB one
// about to be written over it.
struct CrashScene {
  fs::path path;
  Checkpoint old_ckpt = training_checkpoint(5000, 4, 1);
  Checkpoint new_ckpt = training_checkpoint(70000, 40, 2);
  std::string old_bytes, new_bytes;

  explicit CrashScene(const fs::path& p) : path(p) {
    write_checkpoint(fs::path(p) += ".new", new_ckpt);
    new_bytes = read_bytes(fs::path(p) += ".new");
    fs::remove(fs::path(p) += ".new");
    write_checkpoint(path, old_ckpt);
    old_bytes = read_bytes(path);
  }
  // The old checkpoint is in place, byte for byte, and loads bit-exactly.
  void expect_old_intact() const {
    ASSERT_TRUE(read_bytes(path) == old_bytes) << "the old checkpoint was modified or replaced by a partial file";
    expect_same(read_checkpoint(path), old_ckpt);
  }
};

// A signal-killed writer at exact byte positions: RLIMIT_FSIZE makes the kernel deliver
// SIGXFSZ (default action: terminate) on the first write past the limit, so the temporary
// ends up exactly `limit` bytes long - deterministic "kill at any moment".
TEST_F(CheckpointCrash, WriterKilledAtExactBytePositionsLeavesTheOldCheckpoint) {
  const CrashScene scene(file("train.ckpt"));
  const std::uintmax_t total = scene.new_bytes.size();
  ASSERT_GT(total, 45u << 20) << "the new checkpoint should be about 50 MB";
  using U = std::uintmax_t;
  for (U limit : {U{0}, U{1}, U{23}, U{24}, U{100}, total / 4, total / 2, 3 * total / 4, total - 4, total - 1}) {
    SCOPED_TRACE("killed after " + std::to_string(limit) + " of " + std::to_string(total) + " bytes");
    const pid_t pid = spawn_writer(scene.path, scene.new_ckpt, [limit] {
      const rlimit fsize{limit, limit};
      ::setrlimit(RLIMIT_FSIZE, &fsize);
    });
    const int status = wait_for(pid);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGXFSZ) << "status " << status;
    EXPECT_EQ(size_of(tmp_of(scene.path)), limit) << "the partial temporary shows where it died";
    scene.expect_old_intact();
  }
  write_checkpoint(scene.path, scene.new_ckpt);  // the stale temporary is simply replaced
  EXPECT_TRUE(read_bytes(scene.path) == scene.new_bytes);
  EXPECT_FALSE(fs::exists(tmp_of(scene.path)));
}

// The real thing: SIGKILL from outside while the temporary grows, at several fractions.
// Whatever the timing, the file is the old checkpoint while a temporary exists and the new
// one once the rename happened - never anything else.
TEST_F(CheckpointCrash, WriterSigkilledDuringTheWriteLeavesTheOldCheckpoint) {
  const CrashScene scene(file("train.ckpt"));
  const double total = static_cast<double>(scene.new_bytes.size());
  int mid_write_kills = 0;
  for (double fraction : {0.05, 0.3, 0.6, 0.9, 0.99}) {
    for (int attempt = 0; attempt < 5; ++attempt) {
      SCOPED_TRACE("fraction " + std::to_string(fraction) + ", attempt " + std::to_string(attempt));
      fs::remove(tmp_of(scene.path));
      const pid_t pid = spawn_writer(scene.path, scene.new_ckpt, [] {});
      int status = 0;
      bool exited = false;
      for (;;) {  // busy poll: the write takes only tens of milliseconds
        if (::waitpid(pid, &status, WNOHANG) == pid) {
          exited = true;
          break;
        }
        const auto size = size_of(tmp_of(scene.path));
        if (size && static_cast<double>(*size) >= fraction * total) break;
      }
      if (!exited) {
        ::kill(pid, SIGKILL);
        status = wait_for(pid);
      }
      const auto tmp_size = size_of(tmp_of(scene.path));
      if (tmp_size) {  // died before the rename
        ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "status " << status;
        EXPECT_LE(*tmp_size, scene.new_bytes.size());
        scene.expect_old_intact();
        ++mid_write_kills;
        break;
      }
      ASSERT_TRUE(read_bytes(scene.path) == scene.new_bytes) << "renamed, so it must be the complete new file";
      write_checkpoint(scene.path, scene.old_ckpt);  // too late this time; set up again and retry
    }
  }
  EXPECT_GE(mid_write_kills, 3) << "the kills should mostly land mid-write";
  std::printf("[   info   ] %d of 5 SIGKILLs landed mid-write\n", mid_write_kills);
}

// An I/O error mid-stream (EFBIG: SIGXFSZ ignored, file size limit 1 MiB) is reported as a
// CheckpointError naming the file and the cause; old file intact, temporary removed.
TEST_F(CheckpointCrash, FailedWriteMidStreamLeavesTheOldCheckpointAndNoTemporary) {
  const CrashScene scene(file("train.ckpt"));
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit fsize{1 << 20, 1 << 20};
    ::setrlimit(RLIMIT_FSIZE, &fsize);
    std::string message = "(no exception)";
    try {
      write_checkpoint(scene.path, scene.new_ckpt);
    } catch (const CheckpointError& e) {
      message = e.what();
    } catch (...) {
      message = "(an exception other than CheckpointError)";
    }
    [[maybe_unused]] const ssize_t w = ::write(fds[1], message.data(), message.size());
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string message;
  char buf[512];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) message.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  const int status = wait_for(pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_THAT(message,
              AllOf(StartsWith(scene.path.string() + ": write to temporary file"), HasSubstr("File too large")));
  scene.expect_old_intact();
  EXPECT_FALSE(fs::exists(tmp_of(scene.path)));
}

}  // namespace
}  // namespace desplat
