// Training checkpoints: a JSON metadata object (step, config, RNG state, ...) plus named,
// shaped arrays (parameters, optimizer moments, per-view distractor buffers, ...), stored in
// one binary file that is written atomically and read back bit for bit.
//
// Guarantees
//   * Bit-exact: every array element comes back with the same bits (NaN payloads, -0,
//     denormals included: the container never interprets values; checking them is the
//     trainer's job). Metadata comes back equal as JSON; its numbers round-trip exactly
//     (shortest round-trip decimal), but JSON cannot hold NaN/Inf, so the writer refuses them.
//   * Deterministic: equal checkpoints produce identical files (arrays in name order).
//   * Crash-safe: write_checkpoint replaces the file atomically (desplat/atomic_file.hpp), so
//     a crash or kill at any moment leaves the previous checkpoint intact and loadable.
//   * Corruption is detected, never loaded: every section has its own CRC-32; truncation,
//     trailing bytes, bad sizes and shapes are checked, and sizes are checked against the
//     bytes actually present before anything is allocated. The error names the file and the
//     problem (and the section, when it is in one).
// Host byte order must be little-endian (checked at compile time): arrays are copied as-is.
//
// File format, version 1 (all integers little-endian):
//   file header, 24 bytes
//     magic         8 bytes   0x89 'D' 'S' 'C' 'K' 'P' 'T' '\n'
//     version       u32       1
//     section_count u32       sections that follow (>= 1: the metadata)
//     reserved      u32       0
//     header_crc    u32       CRC-32 of the 20 bytes above
//   section_count sections, back to back, each
//     type          u8        0 metadata (UTF-8 JSON text), 1 float32, 2 int32, 3 uint8, 4 uint64
//     rank          u8        0..8 (0: a scalar, one element)
//     name_length   u16       1..255
//     payload_size  u64       product(dims) * element size (1 byte for metadata)
//     dims          u64 * rank
//     name          name_length bytes of printable ASCII other than space (0x21..0x7E)
//     header_crc    u32       CRC-32 of this section's bytes from `type` through `name`
//     payload       payload_size bytes: the elements in row-major order, or the JSON text
//     payload_crc   u32       CRC-32 of the payload
//   Section 0 is the metadata: type 0, rank 1, dims = {payload_size}, name "metadata"; it
//   must be a JSON object. Sections 1.. are arrays with distinct names, written in name order.
//   Nothing follows the last section. CRC-32 is zlib's crc32() (IEEE polynomial 0xEDB88320).
//
// Ownership: Checkpoint is a plain value type owning its arrays. Thread safety: no shared
// state; concurrent writes of the same path are refused (one writer throws).
#pragma once

#include <concepts>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace desplat {

inline constexpr std::uint32_t kCheckpointFormatVersion = 1;
inline constexpr std::size_t kCheckpointMaxRank = 8;
inline constexpr std::size_t kCheckpointMaxNameLength = 255;

// Reading or writing failed. what() starts with the file path when there is one, e.g.
//   "/run/ckpt/step_1000.ckpt: checksum mismatch in section 'static/means' (...)".
class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class ArrayType : std::uint8_t { Float32 = 1, Int32 = 2, UInt8 = 3, UInt64 = 4 };
const char* array_type_name(ArrayType type);  // "float32", ...

template <class T>
concept CheckpointElement = std::same_as<T, float> || std::same_as<T, std::int32_t> || std::same_as<T, std::uint8_t> ||
    std::same_as<T, std::uint64_t>;

// Array names: 1..255 printable ASCII characters other than space, e.g. "static/means",
// "static/adam_m/means", "distractor/17/rgb".
bool is_valid_array_name(std::string_view name);

// A shaped array of one element type. Invariant: values().size() == product(shape()).
class CheckpointArray {
 public:
  using Shape = std::vector<std::uint64_t>;

  CheckpointArray() = default;  // float32, shape {0}
  // Throws std::invalid_argument when the shape's element count differs from values.size()
  // or the rank exceeds kCheckpointMaxRank.
  template <CheckpointElement T>
  CheckpointArray(Shape shape, std::vector<T> values) : shape_(std::move(shape)), values_(std::move(values)) {
    check_invariant();
  }

  ArrayType type() const;
  const Shape& shape() const { return shape_; }
  std::size_t size() const;       // elements
  std::size_t byte_size() const;  // size() * element size
  const void* data() const;       // the elements' bytes, row-major

  template <CheckpointElement T>
  bool holds() const {
    return std::holds_alternative<std::vector<T>>(values_);
  }
  // Throws CheckpointError when T is not the stored element type.
  template <CheckpointElement T>
  const std::vector<T>& values() const {
    if (!holds<T>()) throw_type_mismatch(element_type_of<T>());
    return std::get<std::vector<T>>(values_);
  }

  // Equal type, shape and bytes (so NaN equals the same NaN and -0 differs from +0).
  friend bool operator==(const CheckpointArray& a, const CheckpointArray& b);

  template <CheckpointElement T>
  static constexpr ArrayType element_type_of() {
    if constexpr (std::same_as<T, float>)
      return ArrayType::Float32;
    else if constexpr (std::same_as<T, std::int32_t>)
      return ArrayType::Int32;
    else if constexpr (std::same_as<T, std::uint8_t>)
      return ArrayType::UInt8;
    else
      return ArrayType::UInt64;
  }

 private:
  void check_invariant() const;
  [[noreturn]] void throw_type_mismatch(ArrayType wanted) const;

  Shape shape_{0};
  std::variant<std::vector<float>, std::vector<std::int32_t>, std::vector<std::uint8_t>, std::vector<std::uint64_t>>
      values_;
};

struct Checkpoint {
  using Shape = CheckpointArray::Shape;

  std::uint32_t format_version = kCheckpointFormatVersion;  // of the file it was read from
  nlohmann::json metadata = nlohmann::json::object();
  std::map<std::string, CheckpointArray, std::less<>> arrays;
  // The file it was read from (empty for one built in memory); accessor errors name it.
  // Not part of the value: ignored by ==.
  std::filesystem::path source;

  // Adds or replaces an array. Throws std::invalid_argument for an invalid name or a shape
  // that does not match values.size().
  template <CheckpointElement T>
  void put(const std::string& name, Shape shape, std::vector<T> values) {
    check_name(name);
    arrays.insert_or_assign(name, CheckpointArray(std::move(shape), std::move(values)));
  }

  bool contains(std::string_view name) const { return arrays.find(name) != arrays.end(); }
  // Throw CheckpointError (naming `source`, the array and what was expected) when the array
  // is missing, has another element type, or - for the second form - another shape.
  const CheckpointArray& array(std::string_view name) const;
  template <CheckpointElement T>
  const std::vector<T>& get(std::string_view name) const {
    return checked(name, CheckpointArray::element_type_of<T>(), nullptr).template values<T>();
  }
  template <CheckpointElement T>
  const std::vector<T>& get(std::string_view name, const Shape& expected_shape) const {
    return checked(name, CheckpointArray::element_type_of<T>(), &expected_shape).template values<T>();
  }

  friend bool operator==(const Checkpoint& a, const Checkpoint& b) {
    return a.format_version == b.format_version && a.metadata == b.metadata && a.arrays == b.arrays;
  }

 private:
  static void check_name(const std::string& name);
  const CheckpointArray& checked(std::string_view name, ArrayType type, const Shape* shape) const;
};

// Writes `checkpoint` to `path` atomically (the previous file stays intact on any failure).
// Before touching the file it checks format_version == kCheckpointFormatVersion, that the
// metadata is a JSON object that survives a JSON round trip (no NaN/Inf, valid UTF-8), and
// every array name. Memory: arrays are streamed from where they are; nothing is copied.
// Throws CheckpointError naming `path`.
void write_checkpoint(const std::filesystem::path& path, const Checkpoint& checkpoint);

// Reads and fully verifies a checkpoint (see the format above). Throws CheckpointError
// naming `path` and the problem: missing or unreadable file, bad magic, unsupported version,
// header or section checksum mismatch, truncation, size/shape mismatch, unknown type,
// invalid or duplicate name, missing or invalid metadata, trailing bytes.
// Memory: each array is read straight into its final buffer (peak = the checkpoint's size).
Checkpoint read_checkpoint(const std::filesystem::path& path);

// RNG state as text (the standard's operator<< form), for Checkpoint::metadata.
template <class Engine>
std::string save_rng_state(const Engine& engine) {
  std::ostringstream out;
  out << engine;
  return out.str();
}

// Restores a state written by save_rng_state; draws after it equal the saved engine's.
// Throws CheckpointError (engine unchanged) when `state` is not a complete state.
template <class Engine>
void restore_rng_state(Engine& engine, const std::string& state) {
  std::istringstream in(state);
  Engine restored;
  in >> restored;
  if (in.fail() || !(in >> std::ws).eof())
    throw CheckpointError("invalid RNG state in checkpoint metadata (" + std::to_string(state.size()) +
                          " characters; not a complete engine state)");
  engine = restored;
}

}  // namespace desplat
