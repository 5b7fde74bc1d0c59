// What the COLMAP model checks and both file formats share: whole-file I/O and number formatting
// for messages. Private to the io layer. ColmapError names the path when a file is missing, not
// a regular file, or cannot be read or written.
#pragma once

#include <charconv>
#include <filesystem>
#include <string>
#include <string_view>
#include <type_traits>

namespace desplat::colmap {

std::string read_file(const std::filesystem::path& path);
void write_file(const std::filesystem::path& path, std::string_view bytes);
// Creates `dir` (and parents) for a writer.
void make_directory(const std::filesystem::path& dir);

// Shortest decimal that reads back as the same double: messages show the exact bad value.
inline std::string num(double v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

template <class T>
std::string num(T v) requires std::is_integral_v<T> {
  return std::to_string(v);
}

}  // namespace desplat::colmap
