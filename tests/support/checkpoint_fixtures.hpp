// Shared by the checkpoint tests: a test fixture with its own directory, file helpers, small
// and training-sized checkpoints, a bitwise CRC-32 reference and a builder of raw checkpoint
// bytes from the documented layout.
#pragma once

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>
#include "desplat/io/atomic_file.hpp"
#include "desplat/io/checkpoint.hpp"
#include "io/crc32.hpp"
#include "support/temp_dir.hpp"

namespace desplat::checkpoint_test {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

// ---------------------------------------------------------------------------
// Helpers.

// A test with its own empty directory.
class TempDir : public ::testing::Test {
 protected:
  fs::path file(const std::string& name) const { return dir_ / name; }

  desplat::testing::TempDir tmp_{"ckpt"};
  const fs::path dir_ = tmp_.path();
};
using AtomicFile = TempDir;
using CheckpointFormat = TempDir;
using CheckpointCorruption = TempDir;
using CheckpointCrash = TempDir;

fs::path tmp_of(const fs::path& path) { return fs::path(path) += ".tmp"; }

inline void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

inline std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::uint32_t bits(float v) { return std::bit_cast<std::uint32_t>(v); }

// The CheckpointError message from reading `path`; any other exception fails the test.
inline std::string read_error(const fs::path& path) {
  try {
    read_checkpoint(path);
  } catch (const CheckpointError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

inline std::string write_error(const fs::path& path, const Checkpoint& c) {
  try {
    write_checkpoint(path, c);
  } catch (const CheckpointError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

// Values a careless copy (through float arithmetic, text, or a normalizing load) would change.
inline Checkpoint small_checkpoint() {
  Checkpoint c;
  c.metadata = {
      {"step", 1234},
      {"config", {{"scene", "fox"}, {"sh_degree", 3}, {"lr_means", 1.6e-4}, {"tiny", 4.9e-324}}},
      {"unicode", "Gr\u00fc\u00dfe \u2713"},
      {"u64_max", std::numeric_limits<std::uint64_t>::max()},
      {"i64_min", std::numeric_limits<std::int64_t>::min()},
      {"mixed", {1, 2.5, "x", nullptr, true}},
  };
  c.put<float>("static/means", {2, 3},
               {0.1f, -0.0f, 1e-45f, std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                std::bit_cast<float>(0x7fc01234u)});
  c.put<float>("static/adam_m/means", {2, 3},
               {std::bit_cast<float>(0xff800001u), std::bit_cast<float>(0x7f800001u), std::numeric_limits<float>::min(),
                -1.5f, std::numeric_limits<float>::max(), 3.0f});
  c.put<std::int32_t>("static/ids", {4}, {std::numeric_limits<std::int32_t>::min(), -1, 0, 2147483647});
  c.put<std::uint8_t>("distractor/17/mask", {2, 2, 1}, {0, 1, 128, 255});
  c.put<std::uint64_t>("step_counter", {}, {std::numeric_limits<std::uint64_t>::max()});  // a scalar
  c.put<float>("empty", {0, 3}, {});
  return c;
}

// A training-shaped checkpoint of n static Gaussians (SH degree 3) with Adam moments, plus
// per-view distractor buffers: about 708 bytes per Gaussian.
inline Checkpoint training_checkpoint(std::size_t n, int views, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal;
  const auto floats = [&](std::size_t count) {
    std::vector<float> v(count);
    for (float& x : v) x = normal(rng);
    return v;
  };
  Checkpoint c;
  c.metadata = {{"step", 1000 + seed}, {"config", {{"sh_degree", 3}, {"threads", 2}}}};
  const std::pair<const char*, std::uint64_t> params[] = {
      {"means", 3}, {"log_scales", 3}, {"quats", 4}, {"opacity_logits", 1}, {"colors", 48}};
  for (const auto& [name, width] : params)
    for (const char* group : {"static/", "static/adam_m/", "static/adam_v/"})
      c.put<float>(std::string(group) + name, {n, width}, floats(n * width));
  for (int v = 0; v < views; ++v) {
    c.put<float>("distractor/" + std::to_string(v) + "/means", {64, 3}, floats(64 * 3));
    c.put<std::uint8_t>("distractor/" + std::to_string(v) + "/mask", {40, 60},
                        std::vector<std::uint8_t>(40 * 60, static_cast<std::uint8_t>(v)));
  }
  c.put<std::int32_t>("density/grad_count", {n}, std::vector<std::int32_t>(n, static_cast<std::int32_t>(seed)));
  c.metadata["rng"] = save_rng_state(rng);
  return c;
}

inline void expect_same(const Checkpoint& got, const Checkpoint& want) {
  EXPECT_EQ(got.format_version, want.format_version);
  EXPECT_EQ(got.metadata, want.metadata);
  ASSERT_EQ(got.arrays.size(), want.arrays.size());
  for (const auto& [name, array] : want.arrays) {
    ASSERT_TRUE(got.contains(name)) << name;
    EXPECT_TRUE(got.array(name) == array) << "array '" << name << "' differs in type, shape or bits";
  }
}

// ---------------------------------------------------------------------------
// The test's own encoder, written from the format description in checkpoint.hpp (with its
// own bitwise CRC), so the library is checked against the documentation, not itself.

inline std::uint32_t reference_crc32(const std::string& bytes) {
  std::uint32_t crc = 0xffffffffu;
  for (unsigned char byte : bytes) {
    crc ^= byte;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

template <class T>
inline void append_le(std::string& out, T v) {
  const auto u = static_cast<std::uint64_t>(v);
  for (std::size_t b = 0; b < sizeof(T); ++b) out += static_cast<char>((u >> (8 * b)) & 0xff);
}

struct RawSection {
  std::uint8_t type = 1;
  std::string name;
  std::vector<std::uint64_t> dims;
  std::uint64_t payload_size = 0;
  std::string payload;
};

struct RawFile {
  std::string magic = std::string{'\x89', 'D', 'S', 'C', 'K', 'P', 'T', '\n'};
  std::uint32_t version = 1;
  std::optional<std::uint32_t> section_count;  // default: sections.size()
  std::uint32_t reserved = 0;
  std::vector<RawSection> sections;

  // payload_offsets, when given, receives where each section's payload starts.
  std::string bytes(std::vector<std::size_t>* payload_offsets = nullptr) const {
    std::string out = magic;
    append_le<std::uint32_t>(out, version);
    append_le<std::uint32_t>(out, section_count.value_or(static_cast<std::uint32_t>(sections.size())));
    append_le<std::uint32_t>(out, reserved);
    append_le<std::uint32_t>(out, reference_crc32(out));
    for (const RawSection& s : sections) {
      std::string h;
      append_le<std::uint8_t>(h, s.type);
      append_le<std::uint8_t>(h, static_cast<std::uint8_t>(s.dims.size()));
      append_le<std::uint16_t>(h, static_cast<std::uint16_t>(s.name.size()));
      append_le<std::uint64_t>(h, s.payload_size);
      for (std::uint64_t d : s.dims) append_le<std::uint64_t>(h, d);
      h += s.name;
      append_le<std::uint32_t>(h, reference_crc32(h));
      out += h;
      if (payload_offsets) payload_offsets->push_back(out.size());
      out += s.payload;
      append_le<std::uint32_t>(out, reference_crc32(s.payload));
    }
    return out;
  }
};

RawSection raw_metadata(const std::string& json) { return {0, "metadata", {json.size()}, json.size(), json}; }

template <class T>
inline RawSection raw_array(const std::string& name, std::vector<std::uint64_t> dims, const std::vector<T>& values) {
  std::string payload(values.size() * sizeof(T), '\0');
  if (!payload.empty()) std::memcpy(payload.data(), values.data(), payload.size());  // host is little-endian
  const auto type = static_cast<std::uint8_t>(CheckpointArray::element_type_of<T>());
  return {type, name, std::move(dims), payload.size(), payload};
}

// A valid file: metadata {"step":1}, then arrays "a" (float32 [2, 3]) and "b" (uint8 [5]).
inline RawFile raw_valid() {
  RawFile f;
  f.sections = {raw_metadata(R"({"step":1})"), raw_array<float>("a", {2, 3}, {1, 2, 3, 4, 5, 6}),
                raw_array<std::uint8_t>("b", {5}, {1, 2, 3, 4, 5})};
  return f;
}

}  // namespace desplat::checkpoint_test
