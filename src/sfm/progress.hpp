// Reading COLMAP's output: lines out of a byte stream, and progress reports out of the lines
// each stage prints. Private to the sfm layer.
#pragma once

#include <charconv>
#include <optional>
#include <string>
#include <string_view>

#include "desplat/sfm/sfm.hpp"

namespace desplat::sfm {

// "12/50" at the start of s.
inline bool parse_fraction(std::string_view s, int& a, int& b) {
  const char* end = s.data() + s.size();
  auto r1 = std::from_chars(s.data(), end, a);
  if (r1.ec != std::errc() || r1.ptr == end || *r1.ptr != '/') return false;
  auto r2 = std::from_chars(r1.ptr + 1, end, b);
  return r2.ec == std::errc();
}

// Rest of `line` after `prefix`, or nullopt.
inline std::optional<std::string_view> after(std::string_view line, std::string_view prefix) {
  const size_t at = line.find(prefix);
  if (at == std::string_view::npos) return std::nullopt;
  return line.substr(at + prefix.size());
}

// Turns colmap's output lines into progress reports.
class ProgressParser {
 public:
  ProgressParser(SfmStage stage, int total, const char* unit) {
    p_.stage = stage;
    p_.total = total;
    p_.unit = unit;
  }
  const SfmProgress& current() const { return p_; }

  // True when the line changed the progress.
  bool feed(std::string_view line) {
    switch (p_.stage) {
      case SfmStage::Extract:
        return feed_fraction(line, "Processed file [", "image");
      case SfmStage::Match:
        return feed_match(line);
      case SfmStage::Map:
        return feed_map(line);
    }
    return false;
  }

 private:
  bool feed_fraction(std::string_view line, std::string_view prefix, const char* unit) {
    const auto rest = after(line, prefix);
    int a = 0, b = 0;
    if (!rest || !parse_fraction(*rest, a, b)) return false;
    p_.done = a, p_.total = b, p_.unit = unit;
    return true;
  }
  // Exhaustive: "Matching block [i/n, j/n]" (n² blocks); sequential, spatial: "Matching image [i/n]".
  bool feed_match(std::string_view line) {
    if (feed_fraction(line, "Matching image [", "image")) return true;
    const auto rest = after(line, "Matching block [");
    int i = 0, n = 0, j = 0, m = 0;
    if (!rest || !parse_fraction(*rest, i, n)) return false;
    const auto second = after(*rest, ", ");
    if (!second || !parse_fraction(*second, j, m)) return false;
    p_.done = (i - 1) * m + j, p_.total = n * m, p_.unit = "block";
    return true;
  }
  bool feed_map(std::string_view line) {
    if (after(line, "Initializing with image pair #")) {
      if (started_) ++p_.model;
      started_ = true;
      p_.done = 2;
      return true;
    }
    if (const auto rest = after(line, "Registering image #")) {  // "#6 (3)": 3 once registered
      const auto open = rest->find('(');
      int n = 0;
      if (open == std::string_view::npos) return false;
      const std::string_view num = rest->substr(open + 1);
      if (std::from_chars(num.data(), num.data() + num.size(), n).ec != std::errc()) return false;
      p_.done = n;
      return true;
    }
    if (after(line, "=> Could not register")) {
      p_.done = std::max(0, p_.done - 1);
      return true;
    }
    return false;
  }

  SfmProgress p_;
  bool started_ = false;
};

// Splits a byte stream into lines at '\n' or '\r'.
class LineSplitter {
 public:
  template <class F>
  void feed(std::string_view chunk, F&& on_line) {
    for (char c : chunk) {
      if (c == '\n' || c == '\r') {
        on_line(std::string_view(line_));
        line_.clear();
      } else if (line_.size() < 4096) {  // a runaway line cannot grow without bound
        line_ += c;
      }
    }
  }
  template <class F>
  void finish(F&& on_line) {
    if (!line_.empty()) on_line(std::string_view(line_));
    line_.clear();
  }

 private:
  std::string line_;
};

}  // namespace desplat::sfm
