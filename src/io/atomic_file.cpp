// Atomic file replacement (see include/desplat/io/atomic_file.hpp for the protocol).
#include "desplat/io/atomic_file.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <streambuf>
#include <string>
#include <utility>
#include <vector>

namespace desplat {
namespace fs = std::filesystem;

AtomicWriteError::AtomicWriteError(const fs::path& path, const std::string& step, int errno_value)
    : std::system_error(errno_value, std::generic_category(), path.string() + ": " + step) {}

namespace {

constexpr std::size_t kBufferBytes = std::size_t{1} << 20;

// Unbuffered-by-the-kernel writes of a whole range, retrying short writes and EINTR.
// Returns 0 or the errno of the failure.
int write_all(int fd, const char* data, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd, data, n);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0) return errno;
    if (w == 0) return EIO;  // cannot happen for regular files; do not spin
    data += w;
    n -= static_cast<std::size_t>(w);
  }
  return 0;
}

// A std::streambuf over a file descriptor with a fixed 1 MiB buffer; large writes bypass
// the buffer. It remembers the first errno so the caller can report the real cause
// rather than the stream's generic failure.
class FdStreambuf : public std::streambuf {
 public:
  explicit FdStreambuf(int fd) : fd_(fd), buffer_(kBufferBytes) {
    setp(buffer_.data(), buffer_.data() + buffer_.size());
  }
  int error() const { return error_; }

 protected:
  int_type overflow(int_type ch) override {
    if (flush_buffer() != 0) return traits_type::eof();
    if (traits_type::eq_int_type(ch, traits_type::eof())) return traits_type::not_eof(ch);
    *pptr() = traits_type::to_char_type(ch);
    pbump(1);
    return ch;
  }

  std::streamsize xsputn(const char* s, std::streamsize n) override {
    if (error_ != 0) return 0;
    if (n <= 0) return 0;  // an empty array's data() may be null: never hand it to memcpy
    const auto count = static_cast<std::size_t>(n);
    if (count <= static_cast<std::size_t>(epptr() - pptr())) {
      std::memcpy(pptr(), s, count);
      pbump(static_cast<int>(count));
      return n;
    }
    if (flush_buffer() != 0) return 0;
    if (count < buffer_.size()) return xsputn(s, n);  // fits the now-empty buffer
    error_ = write_all(fd_, s, count);
    return error_ == 0 ? n : 0;
  }

  int sync() override { return flush_buffer() == 0 ? 0 : -1; }

 private:
  int flush_buffer() {
    if (error_ == 0) error_ = write_all(fd_, pbase(), static_cast<std::size_t>(pptr() - pbase()));
    setp(buffer_.data(), buffer_.data() + buffer_.size());
    return error_;
  }

  int fd_;
  std::vector<char> buffer_;
  int error_ = 0;
};

// The locked temporary file. Until commit() succeeds, destruction removes it.
class TempFile {
 public:
  explicit TempFile(const fs::path& target) : target_(target), tmp_(fs::path(target) += ".tmp") {
    // A writer that finishes between our open and our flock has renamed the inode we hold to
    // `target`; writing it would clobber the committed file. Retry with a fresh temporary.
    for (int attempt = 0; attempt < 3; ++attempt)
      if (open_and_lock()) return;
    fail("temporary file " + tmp_.string() + " keeps being replaced by another writer", EBUSY);
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;
  ~TempFile() {
    if (!committed_) ::unlink(tmp_.c_str());  // still ours: we hold the lock
    if (fd_ >= 0) ::close(fd_);
  }

  int fd() const { return fd_; }
  const fs::path& tmp() const { return tmp_; }

  [[noreturn]] void fail(const std::string& step, int errno_value) const {
    throw AtomicWriteError(target_, step, errno_value);
  }

  void commit() {
    if (::fsync(fd_) != 0) fail("fsync of temporary file " + tmp_.string() + " failed", errno);
    if (::rename(tmp_.c_str(), target_.c_str()) != 0) fail("rename of " + tmp_.string() + " over it failed", errno);
    committed_ = true;
    const int fd = std::exchange(fd_, -1);  // closing releases the lock, after the rename
    if (::close(fd) != 0) fail("was replaced, but closing it failed", errno);
    sync_directory();
  }

 private:
  bool open_and_lock() {
    fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
    if (fd_ < 0) fail("cannot create temporary file " + tmp_.string(), errno);
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      close_quietly();
      if (err == EWOULDBLOCK)
        fail("another writer is writing it (temporary file " + tmp_.string() + " is locked)", err);
      fail("cannot lock temporary file " + tmp_.string(), err);
    }
    struct stat held {
    }, named{};
    if (::fstat(fd_, &held) != 0) fail_closing("cannot stat temporary file " + tmp_.string());
    if (::stat(tmp_.c_str(), &named) != 0 || held.st_ino != named.st_ino || held.st_dev != named.st_dev) {
      close_quietly();
      return false;
    }
    if (!S_ISREG(held.st_mode)) {
      close_quietly();
      fail("temporary file " + tmp_.string() + " exists and is not a regular file", EEXIST);
    }
    if (::ftruncate(fd_, 0) != 0) fail_closing("cannot truncate temporary file " + tmp_.string());
    return true;
  }

  [[noreturn]] void fail_closing(const std::string& step) {
    const int err = errno;
    close_quietly();
    fail(step, err);
  }

  void close_quietly() {
    ::close(fd_);
    fd_ = -1;
  }

  // Makes the rename durable. Filesystems that cannot fsync a directory (EINVAL) give no
  // stronger guarantee to have; anything else is a real error worth reporting.
  void sync_directory() const {
    const fs::path dir = target_.has_parent_path() ? target_.parent_path() : fs::path(".");
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0) fail("was replaced, but its directory cannot be opened for fsync", errno);
    const int rc = ::fsync(dfd);
    const int err = errno;
    ::close(dfd);
    if (rc != 0 && err != EINVAL)
      fail("was replaced, but fsync of directory " + dir.string() +
               " failed (the replacement may not survive a power loss)",
           err);
  }

  fs::path target_, tmp_;
  int fd_ = -1;
  bool committed_ = false;
};

// Runs `writer` on a stream over the temporary; I/O errors surface as AtomicWriteError.
void stream_into(TempFile& file, const std::function<void(std::ostream&)>& writer) {
  FdStreambuf buf(file.fd());
  std::ostream out(&buf);
  out.exceptions(std::ios::badbit);
  try {
    writer(out);
    out.flush();
  } catch (...) {
    // The stream's own failure is only a symptom; report the errno behind it.
    if (buf.error() != 0) file.fail("write to temporary file " + file.tmp().string() + " failed", buf.error());
    throw;
  }
  if (buf.error() != 0) file.fail("write to temporary file " + file.tmp().string() + " failed", buf.error());
  if (!out) file.fail("the writer left its output stream in a failed state", EIO);
}

}  // namespace

void write_file_atomically(const fs::path& path, const std::function<void(std::ostream&)>& writer) {
  TempFile file(path);
  stream_into(file, writer);
  file.commit();
}

void write_file_atomically(const fs::path& path, std::string_view bytes) {
  write_file_atomically(
      path, [bytes](std::ostream& out) { out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())); });
}

}  // namespace desplat
