// Crash-safe file replacement: readers of `path` see either the old file or the complete
// new one, never a partial write, even if the writer is killed or the machine loses power.
//
// Protocol (POSIX):
//   1. open "<path>.tmp" in the same directory (so the rename cannot cross filesystems),
//      take an exclusive non-blocking flock on it and truncate it;
//   2. stream the caller's bytes into it through a fixed-size buffer (memory use does not
//      grow with the file size);
//   3. flush, fsync the temporary, rename it over `path`, fsync the directory so the rename
//      itself is durable.
// On any failure before the rename (an exception from the caller's writer, an I/O error,
// a full disk) the temporary is removed and `path` is untouched: its old contents, or its
// absence, are exactly as before the call.
//
// Crashes: a process killed mid-write leaves at most one stale "<path>.tmp"; the next write
// to `path` reuses and replaces it, so crashes never accumulate temporaries.
// Concurrency: two writers of the same `path` at the same time are refused (the second one
// throws) instead of interleaving their bytes; writers of different paths are independent.
// Readers never need a lock.
// Caveats: the new file gets mode 0644 (minus the umask), not the old file's mode; a
// symlink at `path` is replaced by the file, not followed; "<path>.tmp" must not be a
// symlink (refused).
#pragma once

#include <filesystem>
#include <functional>
#include <ostream>
#include <string>
#include <string_view>
#include <system_error>

namespace desplat {

// An I/O failure of the protocol itself. what() starts with the target path, then says
// which step failed and why, e.g.
//   "/run/a.ckpt: write to temporary file /run/a.ckpt.tmp failed: No space left on device".
// code() holds the errno value.
class AtomicWriteError : public std::system_error {
 public:
  AtomicWriteError(const std::filesystem::path& path, const std::string& step, int errno_value);
};

// Replaces `path` by the bytes `writer` puts into the stream it is given.
// The stream is unformatted-I/O friendly (use write()); it throws std::ios_base::failure on
// a failed write so the writer stops early, and that case is reported as AtomicWriteError
// with the underlying errno. An exception thrown by `writer` itself is rethrown unchanged
// after cleanup. A writer that returns with the stream in a failed state counts as a failure.
// Throws AtomicWriteError for I/O errors (including a concurrent writer of the same path).
// If only the final directory fsync fails, `path` already holds the new contents and the
// error says so.
void write_file_atomically(const std::filesystem::path& path, const std::function<void(std::ostream&)>& writer);

// Convenience for contents that are already in memory.
void write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

}  // namespace desplat
