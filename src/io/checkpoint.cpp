// Checkpoint container (see include/desplat/io/checkpoint.hpp for the file format) and the
// CRC-32 it uses (src/io/crc32.hpp).
#include "desplat/io/checkpoint.hpp"
#include "desplat/io/json_text.hpp"

#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <ostream>
#include <string>
#include <system_error>
#include <utility>

#include "desplat/io/atomic_file.hpp"
#include "io/crc32.hpp"

namespace desplat {

static_assert(std::endian::native == std::endian::little,
              "checkpoint arrays are copied as-is and the format is little-endian");

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------
// CRC-32, slicing by 8 (eight bytes per table round instead of one; checkpoints are large).

namespace detail {
namespace {

using CrcTables = std::array<std::array<std::uint32_t, 256>, 8>;

constexpr CrcTables make_crc_tables() {
  CrcTables t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (std::size_t s = 1; s < 8; ++s)
    for (std::size_t i = 0; i < 256; ++i) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xff];
  return t;
}

constexpr CrcTables kCrcTables = make_crc_tables();

std::uint32_t load_le32(const unsigned char* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
}

}  // namespace

std::uint32_t crc32_update(std::uint32_t crc, const void* data, std::size_t n) {
  const auto& t = kCrcTables;
  const auto* p = static_cast<const unsigned char*>(data);
  crc = ~crc;
  for (; n >= 8; p += 8, n -= 8) {
    const std::uint32_t lo = crc ^ load_le32(p), hi = load_le32(p + 4);
    crc = t[7][lo & 0xff] ^ t[6][(lo >> 8) & 0xff] ^ t[5][(lo >> 16) & 0xff] ^ t[4][lo >> 24] ^ t[3][hi & 0xff] ^
          t[2][(hi >> 8) & 0xff] ^ t[1][(hi >> 16) & 0xff] ^ t[0][hi >> 24];
  }
  for (; n > 0; ++p, --n) crc = t[0][(crc ^ *p) & 0xff] ^ (crc >> 8);
  return ~crc;
}

}  // namespace detail

namespace {

constexpr std::array<unsigned char, 8> kMagic = {0x89, 'D', 'S', 'C', 'K', 'P', 'T', '\n'};
constexpr std::size_t kFileHeaderBytes = 24;
constexpr std::size_t kSectionFixedBytes = 1 + 1 + 2 + 8;  // type, rank, name_length, payload_size
// Fixed part, a 1-byte name and both CRCs: bounds the section count by the file size.
constexpr std::size_t kSectionMinBytes = kSectionFixedBytes + 1 + 4 + 4;
constexpr std::uint8_t kMetadataType = 0;
constexpr const char* kMetadataName = "metadata";

std::string num(std::uint64_t v) { return std::to_string(v); }

std::size_t element_bytes(ArrayType type) {
  switch (type) {
    case ArrayType::Float32:
    case ArrayType::Int32:
      return 4;
    case ArrayType::UInt8:
      return 1;
    case ArrayType::UInt64:
      return 8;
  }
  return 0;
}

bool is_array_type(std::uint8_t t) { return t >= 1 && t <= 4; }

// Element count of a shape; nullopt when it does not fit in 64 bits.
std::optional<std::uint64_t> element_count(const CheckpointArray::Shape& shape) {
  std::uint64_t n = 1;
  for (std::uint64_t d : shape) {
    if (d != 0 && n > std::numeric_limits<std::uint64_t>::max() / d) return std::nullopt;
    n *= d;
  }
  return n;
}

std::string shape_text(const CheckpointArray::Shape& shape) {
  std::string s = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + num(shape[i]);
  return s + "]";
}

std::string hex32(std::uint32_t v) {
  char buf[11];
  std::snprintf(buf, sizeof buf, "0x%08x", v);
  return buf;
}

std::string quoted(const std::string& name) { return "'" + name + "'"; }

// Little-endian field encoding into a byte string.
template <class T>
void put_le(std::string& out, T v) {
  const auto u = static_cast<std::uint64_t>(v);
  for (std::size_t b = 0; b < sizeof(T); ++b) out += static_cast<char>((u >> (8 * b)) & 0xff);
}

template <class T>
T get_le(const unsigned char* p) {
  std::uint64_t v = 0;
  for (std::size_t b = 0; b < sizeof(T); ++b) v |= std::uint64_t{p[b]} << (8 * b);
  return static_cast<T>(v);
}

}  // namespace

// ---------------------------------------------------------------------------
// Value types.

const char* array_type_name(ArrayType type) {
  switch (type) {
    case ArrayType::Float32:
      return "float32";
    case ArrayType::Int32:
      return "int32";
    case ArrayType::UInt8:
      return "uint8";
    case ArrayType::UInt64:
      return "uint64";
  }
  return "unknown";
}

bool is_valid_array_name(std::string_view name) {
  if (name.empty() || name.size() > kCheckpointMaxNameLength) return false;
  for (char c : name)
    if (c < 0x21 || c > 0x7e) return false;
  return true;
}

ArrayType CheckpointArray::type() const {
  return std::visit([](const auto& v) { return element_type_of<typename std::decay_t<decltype(v)>::value_type>(); },
                    values_);
}

std::size_t CheckpointArray::size() const {
  return std::visit([](const auto& v) { return v.size(); }, values_);
}

std::size_t CheckpointArray::byte_size() const { return size() * element_bytes(type()); }

const void* CheckpointArray::data() const {
  return std::visit([](const auto& v) -> const void* { return v.data(); }, values_);
}

void CheckpointArray::check_invariant() const {
  if (shape_.size() > kCheckpointMaxRank)
    throw std::invalid_argument("checkpoint array rank " + num(shape_.size()) + " exceeds " + num(kCheckpointMaxRank));
  const auto n = element_count(shape_);
  if (!n || *n != size())
    throw std::invalid_argument("checkpoint array shape " + shape_text(shape_) + " does not match its " + num(size()) +
                                " values");
}

void CheckpointArray::throw_type_mismatch(ArrayType wanted) const {
  throw CheckpointError(std::string("checkpoint array holds ") + array_type_name(type()) + ", not " +
                        array_type_name(wanted));
}

bool operator==(const CheckpointArray& a, const CheckpointArray& b) {
  return a.type() == b.type() && a.shape_ == b.shape_ &&
         (a.byte_size() == 0 || std::memcmp(a.data(), b.data(), a.byte_size()) == 0);
}

void Checkpoint::check_name(const std::string& name) {
  if (!is_valid_array_name(name))
    throw std::invalid_argument("invalid checkpoint array name '" + name +
                                "' (need 1..255 printable ASCII characters, no spaces)");
}

const CheckpointArray& Checkpoint::array(std::string_view name) const { return checked(name, ArrayType{}, nullptr); }

const CheckpointArray& Checkpoint::checked(std::string_view name, ArrayType type, const Shape* shape) const {
  const std::string where =
      (source.empty() ? std::string("checkpoint") : source.string()) + ": array '" + std::string(name) + "'";
  const auto it = arrays.find(name);
  if (it == arrays.end()) throw CheckpointError(where + " is missing");
  const CheckpointArray& a = it->second;
  if (type != ArrayType{} && a.type() != type)
    throw CheckpointError(where + " holds " + array_type_name(a.type()) + ", expected " + array_type_name(type));
  if (shape && a.shape() != *shape)
    throw CheckpointError(where + " has shape " + shape_text(a.shape()) + ", expected " + shape_text(*shape));
  return a;
}

// ---------------------------------------------------------------------------
// Writing.

namespace {

[[noreturn]] void fail(const fs::path& path, const std::string& what) {
  throw CheckpointError(path.string() + ": " + what);
}

// The metadata as JSON text, after checking that reading it back gives the same value:
// nlohmann silently writes NaN/Inf as null, which would not restore what was saved.
std::string metadata_text(const fs::path& path, const nlohmann::json& metadata) {
  if (!metadata.is_object()) fail(path, std::string("metadata must be a JSON object, not ") + metadata.type_name());
  std::string text;
  try {
    text = metadata.dump();
  } catch (const nlohmann::json::exception& e) {
    fail(path, std::string("metadata cannot be written as JSON: ") + e.what());
  }
  if (nlohmann::json::parse(text) != metadata)
    fail(path, "metadata does not survive a JSON round trip (NaN or infinite numbers?)");
  return text;
}

void check_writable(const fs::path& path, const Checkpoint& c) {
  if (c.format_version != kCheckpointFormatVersion)
    fail(path, "cannot write format version " + num(c.format_version) + "; this build writes version " +
                   num(kCheckpointFormatVersion));
  for (const auto& [name, array] : c.arrays)
    if (!is_valid_array_name(name))
      fail(path, "invalid array name '" + name + "' (need 1..255 printable ASCII characters, no spaces)");
}

void write_bytes(std::ostream& out, const void* data, std::size_t n) {
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(n));
}

std::string file_header(std::uint32_t section_count) {
  std::string h(kMagic.begin(), kMagic.end());
  put_le<std::uint32_t>(h, kCheckpointFormatVersion);
  put_le<std::uint32_t>(h, section_count);
  put_le<std::uint32_t>(h, 0);
  put_le<std::uint32_t>(h, detail::crc32_update(0, h.data(), h.size()));
  return h;
}

void write_section(std::ostream& out, std::uint8_t type, const std::string& name, const CheckpointArray::Shape& dims,
                   const void* payload, std::size_t payload_bytes) {
  std::string h;
  put_le<std::uint8_t>(h, type);
  put_le<std::uint8_t>(h, static_cast<std::uint8_t>(dims.size()));
  put_le<std::uint16_t>(h, static_cast<std::uint16_t>(name.size()));
  put_le<std::uint64_t>(h, payload_bytes);
  for (std::uint64_t d : dims) put_le<std::uint64_t>(h, d);
  h += name;
  put_le<std::uint32_t>(h, detail::crc32_update(0, h.data(), h.size()));
  write_bytes(out, h.data(), h.size());
  write_bytes(out, payload, payload_bytes);
  std::string crc;
  put_le<std::uint32_t>(crc, detail::crc32_update(0, payload, payload_bytes));
  write_bytes(out, crc.data(), crc.size());
}

}  // namespace

void write_checkpoint(const fs::path& path, const Checkpoint& checkpoint) {
  check_writable(path, checkpoint);
  const std::string meta = metadata_text(path, checkpoint.metadata);
  if (checkpoint.arrays.size() >= std::numeric_limits<std::uint32_t>::max())
    fail(path, "too many arrays (" + num(checkpoint.arrays.size()) + ")");
  const auto write_all = [&](std::ostream& out) {
    const std::string header = file_header(static_cast<std::uint32_t>(checkpoint.arrays.size() + 1));
    write_bytes(out, header.data(), header.size());
    write_section(out, kMetadataType, kMetadataName, {meta.size()}, meta.data(), meta.size());
    for (const auto& [name, array] : checkpoint.arrays)
      write_section(out, static_cast<std::uint8_t>(array.type()), name, array.shape(), array.data(), array.byte_size());
  };
  try {
    write_file_atomically(path, write_all);
  } catch (const AtomicWriteError& e) {
    throw CheckpointError(e.what());  // starts with the path already
  }
}

// ---------------------------------------------------------------------------
// Reading.

namespace {

// Sequential, bounds-checked reads of one file: a read past the end is reported as
// truncation with the offset and the item being read.
class Reader {
 public:
  explicit Reader(const fs::path& path) : path_(path), in_(path, std::ios::binary) {
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (status.type() == fs::file_type::not_found) fail("file does not exist");
    if (ec) fail("cannot access: " + ec.message());
    if (!fs::is_regular_file(status)) fail("not a regular file");
    if (!in_) fail("cannot open for reading: " + std::error_code(errno, std::generic_category()).message());
    // The size of the file we hold open, not of whatever the path names by now.
    in_.seekg(0, std::ios::end);
    const std::streamoff end = in_.tellg();
    in_.seekg(0);
    if (end < 0 || !in_) fail("cannot get the file size");
    size_ = static_cast<std::uint64_t>(end);
  }

  [[noreturn]] void fail(const std::string& what) const { desplat::fail(path_, what); }

  std::uint64_t offset() const { return offset_; }
  std::uint64_t remaining() const { return size_ - offset_; }
  std::uint64_t size() const { return size_; }

  void read(void* dst, std::uint64_t n, const std::string& what) {
    if (n > remaining())
      fail("truncated: " + what + " needs " + num(n) + " bytes at offset " + num(offset_) + ", only " +
           num(remaining()) + " left");
    if (n > 0 && !in_.read(static_cast<char*>(dst), static_cast<std::streamsize>(n)))
      fail("read error at offset " + num(offset_) + " (file changed while reading?)");
    offset_ += n;
  }

  template <class T>
  T read_le(const std::string& what) {
    unsigned char b[sizeof(T)];
    read(b, sizeof(T), what);
    return get_le<T>(b);
  }

 private:
  const fs::path& path_;
  std::ifstream in_;
  std::uint64_t size_ = 0, offset_ = 0;
};

std::uint32_t read_file_header(Reader& r) {
  unsigned char h[kFileHeaderBytes];
  if (r.size() < kFileHeaderBytes)
    r.fail("not a checkpoint: truncated: " + num(r.size()) + " bytes, shorter than the " + num(kFileHeaderBytes) +
           "-byte file header");
  r.read(h, kFileHeaderBytes, "file header");
  if (std::memcmp(h, kMagic.data(), kMagic.size()) != 0) r.fail("not a desplat checkpoint (bad magic number)");
  const auto version = get_le<std::uint32_t>(h + 8);
  if (version != kCheckpointFormatVersion)
    r.fail("unsupported checkpoint format version " + num(version) + " (this build reads version " +
           num(kCheckpointFormatVersion) + ")");
  const auto stored = get_le<std::uint32_t>(h + 20), computed = detail::crc32_update(0, h, 20);
  if (stored != computed)
    r.fail("file header checksum mismatch (stored " + hex32(stored) + ", computed " + hex32(computed) + ")");
  if (get_le<std::uint32_t>(h + 16) != 0) r.fail("reserved file header field is not 0");
  const auto count = get_le<std::uint32_t>(h + 12);
  if (count == 0) r.fail("no sections (the metadata section is required)");
  if (count > r.remaining() / kSectionMinBytes)
    r.fail("header declares " + num(count) + " sections, but the " + num(r.remaining()) +
           " bytes after the header can hold at most " + num(r.remaining() / kSectionMinBytes) + " (truncated?)");
  return count;
}

struct SectionHeader {
  std::uint8_t type = 0;
  std::string name;
  CheckpointArray::Shape dims;
  std::uint64_t payload_bytes = 0;
};

// Reads and checksums one section header; everything in it is trustworthy afterwards.
SectionHeader read_section_header(Reader& r, std::uint32_t index) {
  const std::string where = "section #" + num(index) + " (offset " + num(r.offset()) + ")";
  unsigned char fixed[kSectionFixedBytes];
  r.read(fixed, kSectionFixedBytes, where + " header");
  SectionHeader h;
  h.type = fixed[0];
  const std::size_t rank = fixed[1], name_length = get_le<std::uint16_t>(fixed + 2);
  h.payload_bytes = get_le<std::uint64_t>(fixed + 4);
  // Bounded before use, so a corrupt header cannot make us read or allocate much.
  if (rank > kCheckpointMaxRank)
    r.fail(where + ": rank " + num(rank) + " exceeds " + num(kCheckpointMaxRank) + " (corrupt header)");
  if (name_length == 0 || name_length > kCheckpointMaxNameLength)
    r.fail(where + ": name length " + num(name_length) + " is not in 1..255 (corrupt header)");

  std::string rest(8 * rank + name_length, '\0');
  r.read(rest.data(), rest.size(), where + " header");
  const auto stored = r.read_le<std::uint32_t>(where + " header checksum");
  const auto computed = detail::crc32_update(detail::crc32_update(0, fixed, sizeof fixed), rest.data(), rest.size());
  if (stored != computed)
    r.fail(where + ": header checksum mismatch (stored " + hex32(stored) + ", computed " + hex32(computed) + ")");
  for (std::size_t d = 0; d < rank; ++d)
    h.dims.push_back(get_le<std::uint64_t>(reinterpret_cast<const unsigned char*>(rest.data()) + 8 * d));
  h.name = rest.substr(8 * rank);
  if (!is_valid_array_name(h.name)) r.fail(where + ": invalid section name (not printable ASCII)");
  return h;
}

// The payload size the header's type and shape imply, checked against the declared one.
void check_payload_size(Reader& r, const SectionHeader& h, std::size_t elem_bytes) {
  const std::string where = "section " + quoted(h.name);
  const auto n = element_count(h.dims);
  if (!n || *n > std::numeric_limits<std::uint64_t>::max() / elem_bytes)
    r.fail(where + ": shape " + shape_text(h.dims) + " is too large (element count overflows)");
  if (*n * elem_bytes != h.payload_bytes)
    r.fail(where + ": shape " + shape_text(h.dims) + " of " + num(elem_bytes) + "-byte elements needs " +
           num(*n * elem_bytes) + " bytes, but the section declares " + num(h.payload_bytes));
  // Before allocating: the payload and its checksum must be in the file.
  if (h.payload_bytes > r.remaining() || r.remaining() - h.payload_bytes < 4)
    r.fail("truncated: " + where + " declares " + num(h.payload_bytes) +
           " payload bytes plus a 4-byte checksum at offset " + num(r.offset()) + ", only " + num(r.remaining()) +
           " bytes left");
}

void read_payload(Reader& r, const SectionHeader& h, void* dst) {
  r.read(dst, h.payload_bytes, "section " + quoted(h.name) + " payload");
  const auto stored = r.read_le<std::uint32_t>("section " + quoted(h.name) + " checksum");
  const auto computed = detail::crc32_update(0, dst, h.payload_bytes);
  if (stored != computed)
    r.fail("checksum mismatch in section " + quoted(h.name) + " (stored " + hex32(stored) + ", computed " +
           hex32(computed) + "): the data is corrupt");
}

nlohmann::json read_metadata(Reader& r, const SectionHeader& h) {
  if (h.type != kMetadataType || h.name != kMetadataName)
    r.fail("the first section must be the metadata, found " + quoted(h.name) + " of type " + num(h.type));
  if (h.dims.size() != 1) r.fail("metadata section has rank " + num(h.dims.size()) + ", expected 1");
  check_payload_size(r, h, 1);
  std::string text(h.payload_bytes, '\0');
  read_payload(r, h, text.data());
  nlohmann::json meta;
  try {
    meta = parse_json_bounded(text, "metadata");
  } catch (const JsonTextError& e) {
    r.fail(e.what());
  } catch (const nlohmann::json::exception& e) {
    r.fail(std::string("metadata is not valid JSON: ") + e.what());
  }
  if (!meta.is_object()) r.fail(std::string("metadata is a JSON ") + meta.type_name() + ", expected an object");
  return meta;
}

template <CheckpointElement T>
CheckpointArray read_values(Reader& r, const SectionHeader& h) {
  check_payload_size(r, h, sizeof(T));
  std::vector<T> values(h.payload_bytes / sizeof(T));
  read_payload(r, h, values.data());
  return CheckpointArray(h.dims, std::move(values));
}

CheckpointArray read_array(Reader& r, const SectionHeader& h) {
  switch (static_cast<ArrayType>(h.type)) {
    case ArrayType::Float32:
      return read_values<float>(r, h);
    case ArrayType::Int32:
      return read_values<std::int32_t>(r, h);
    case ArrayType::UInt8:
      return read_values<std::uint8_t>(r, h);
    case ArrayType::UInt64:
      return read_values<std::uint64_t>(r, h);
  }
  r.fail("section " + quoted(h.name) + ": unknown element type " + num(h.type));
}

}  // namespace

Checkpoint read_checkpoint(const fs::path& path) {
  Reader r(path);
  const std::uint32_t count = read_file_header(r);
  Checkpoint c;
  c.format_version = kCheckpointFormatVersion;
  c.metadata = read_metadata(r, read_section_header(r, 0));
  for (std::uint32_t i = 1; i < count; ++i) {
    const SectionHeader h = read_section_header(r, i);
    if (!is_array_type(h.type))
      r.fail("section " + quoted(h.name) + ": unknown element type " + num(h.type) +
             (h.type == kMetadataType ? " (a second metadata section)" : ""));
    if (c.contains(h.name)) r.fail("duplicate array " + quoted(h.name));
    c.arrays.emplace(h.name, read_array(r, h));
  }
  if (r.remaining() > 0) r.fail(num(r.remaining()) + " trailing bytes after the last of " + num(count) + " sections");
  c.source = path;
  return c;
}

}  // namespace desplat
