// Checkpoints and atomic file replacement: bit-exact round trips, the documented byte layout
// (checked against the test's own encoder), one clear CheckpointError per kind of corruption,
// and crash safety: a writer killed at many moments of a ~50 MB write, or failing mid-stream,
// leaves the previous checkpoint byte-identical and loadable.
#include <gmock/gmock.h>
#include <fcntl.h>
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

namespace desplat {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

// ---------------------------------------------------------------------------
// Helpers.

class TempDir : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("desplat_test_ckpt_" + std::to_string(::getpid()) + "_" +
                                        info->test_suite_name() + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path file(const std::string& name) const { return dir_ / name; }

  fs::path dir_;
};
using AtomicFile = TempDir;
using CheckpointFormat = TempDir;
using CheckpointCorruption = TempDir;
using CheckpointCrash = TempDir;

fs::path tmp_of(const fs::path& path) { return fs::path(path) += ".tmp"; }

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::uint32_t bits(float v) { return std::bit_cast<std::uint32_t>(v); }

// The CheckpointError message from reading `path`; any other exception fails the test.
std::string read_error(const fs::path& path) {
  try {
    read_checkpoint(path);
  } catch (const CheckpointError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

std::string write_error(const fs::path& path, const Checkpoint& c) {
  try {
    write_checkpoint(path, c);
  } catch (const CheckpointError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

// Values a careless copy (through float arithmetic, text, or a normalizing load) would change.
Checkpoint small_checkpoint() {
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
               {0.1f, -0.0f, 1e-45f, std::numeric_limits<float>::infinity(),
                -std::numeric_limits<float>::infinity(), std::bit_cast<float>(0x7fc01234u)});
  c.put<float>("static/adam_m/means", {2, 3},
               {std::bit_cast<float>(0xff800001u), std::bit_cast<float>(0x7f800001u),
                std::numeric_limits<float>::min(), -1.5f, std::numeric_limits<float>::max(), 3.0f});
  c.put<std::int32_t>("static/ids", {4}, {std::numeric_limits<std::int32_t>::min(), -1, 0, 2147483647});
  c.put<std::uint8_t>("distractor/17/mask", {2, 2, 1}, {0, 1, 128, 255});
  c.put<std::uint64_t>("step_counter", {}, {std::numeric_limits<std::uint64_t>::max()});  // a scalar
  c.put<float>("empty", {0, 3}, {});
  return c;
}

// A training-shaped checkpoint of n static Gaussians (SH degree 3) with Adam moments, plus
// per-view distractor buffers: about 708 bytes per Gaussian.
Checkpoint training_checkpoint(std::size_t n, int views, std::uint64_t seed) {
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
  c.put<std::int32_t>("density/grad_count", {n},
                      std::vector<std::int32_t>(n, static_cast<std::int32_t>(seed)));
  c.metadata["rng"] = save_rng_state(rng);
  return c;
}

void expect_same(const Checkpoint& got, const Checkpoint& want) {
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

std::uint32_t reference_crc32(const std::string& bytes) {
  std::uint32_t crc = 0xffffffffu;
  for (unsigned char byte : bytes) {
    crc ^= byte;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

template <class T>
void append_le(std::string& out, T v) {
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
RawSection raw_array(const std::string& name, std::vector<std::uint64_t> dims, const std::vector<T>& values) {
  std::string payload(values.size() * sizeof(T), '\0');
  if (!payload.empty()) std::memcpy(payload.data(), values.data(), payload.size());  // host is little-endian
  const auto type = static_cast<std::uint8_t>(CheckpointArray::element_type_of<T>());
  return {type, name, std::move(dims), payload.size(), payload};
}

// A valid file: metadata {"step":1}, then arrays "a" (float32 [2, 3]) and "b" (uint8 [5]).
RawFile raw_valid() {
  RawFile f;
  f.sections = {raw_metadata(R"({"step":1})"), raw_array<float>("a", {2, 3}, {1, 2, 3, 4, 5, 6}),
                raw_array<std::uint8_t>("b", {5}, {1, 2, 3, 4, 5})};
  return f;
}

// ---------------------------------------------------------------------------
// CRC-32.

TEST(Crc32, MatchesKnownVectorsAndTheBitwiseReference) {
  const auto crc = [](const std::string& s) { return detail::crc32_update(0, s.data(), s.size()); };
  EXPECT_EQ(crc(""), 0u);
  EXPECT_EQ(crc("a"), 0xe8b7be43u);
  EXPECT_EQ(crc("123456789"), 0xcbf43926u);
  EXPECT_EQ(crc("The quick brown fox jumps over the lazy dog"), 0x414fa339u);

  // The 8-byte fast path must agree with the bytewise one at every length, alignment and split.
  std::mt19937 rng(5);
  std::string buf(300, '\0');
  for (char& ch : buf) ch = static_cast<char>(rng());
  for (std::size_t start = 0; start < 9; ++start)
    for (std::size_t len = 0; start + len <= buf.size(); len += 7) {
      const std::string piece = buf.substr(start, len);
      const std::uint32_t want = reference_crc32(piece);
      ASSERT_EQ(crc(piece), want) << "start " << start << " len " << len;
      const std::size_t split = len / 3;
      const std::uint32_t head = detail::crc32_update(0, piece.data(), split);
      ASSERT_EQ(detail::crc32_update(head, piece.data() + split, len - split), want);
    }
}

// ---------------------------------------------------------------------------
// Atomic file replacement.

TEST_F(AtomicFile, CreatesThenReplacesAndLeavesNoTemporary) {
  const fs::path path = file("f.bin");
  write_file_atomically(path, "first");
  EXPECT_EQ(read_bytes(path), "first");
  write_file_atomically(path, [](std::ostream& out) {
    const std::string big(3 << 20, 'x');  // larger than the internal buffer: written directly
    out.write(big.data(), static_cast<std::streamsize>(big.size()));
    out << "tail";
  });
  EXPECT_EQ(read_bytes(path), std::string(3 << 20, 'x') + "tail");
  EXPECT_FALSE(fs::exists(tmp_of(path)));
}

TEST_F(AtomicFile, WriterExceptionPropagatesUnchangedAndLeavesTheOldFile) {
  const fs::path path = file("f.bin");
  write_bytes(path, "old contents");
  const auto throwing_writer = [](std::ostream& out) {
    const std::string chunk(3 << 20, 'n');  // some of it reaches the temporary first
    out.write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    throw std::domain_error("writer gave up");
  };
  try {
    write_file_atomically(path, throwing_writer);
    FAIL() << "no exception";
  } catch (const std::domain_error& e) {
    EXPECT_STREQ(e.what(), "writer gave up");
  }
  EXPECT_EQ(read_bytes(path), "old contents");
  EXPECT_FALSE(fs::exists(tmp_of(path)));

  const fs::path fresh = file("never.bin");  // no old file: none appears
  EXPECT_THROW(write_file_atomically(fresh, throwing_writer), std::domain_error);
  EXPECT_FALSE(fs::exists(fresh));
  EXPECT_FALSE(fs::exists(tmp_of(fresh)));
}

TEST_F(AtomicFile, StaleTemporaryFromACrashIsReplaced) {
  const fs::path path = file("f.bin");
  write_bytes(tmp_of(path), std::string(10000, 'g'));  // longer than the new contents
  write_file_atomically(path, "new");
  EXPECT_EQ(read_bytes(path), "new");
  EXPECT_FALSE(fs::exists(tmp_of(path)));
}

TEST_F(AtomicFile, ConcurrentWriterOfTheSamePathIsRefused) {
  const fs::path path = file("f.bin");
  write_bytes(path, "old");
  const int fd = ::open(tmp_of(path).c_str(), O_WRONLY | O_CREAT, 0644);  // a writer in progress
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX), 0);
  try {
    write_file_atomically(path, "mine");
    FAIL() << "no exception";
  } catch (const AtomicWriteError& e) {
    EXPECT_THAT(e.what(), AllOf(StartsWith(path.string() + ": "), HasSubstr("another writer")));
    EXPECT_EQ(e.code().value(), EWOULDBLOCK);
  }
  EXPECT_EQ(read_bytes(path), "old");
  EXPECT_TRUE(fs::exists(tmp_of(path))) << "the other writer's temporary must not be removed";
  ::close(fd);
  write_file_atomically(path, "mine");
  EXPECT_EQ(read_bytes(path), "mine");
}

TEST_F(AtomicFile, ErrorsNameTheFileAndTheStep) {
  const fs::path missing_dir = file("no/such/dir/f.bin");
  try {
    write_file_atomically(missing_dir, "x");
    FAIL() << "no exception";
  } catch (const AtomicWriteError& e) {
    EXPECT_THAT(e.what(), AllOf(StartsWith(missing_dir.string() + ": "), HasSubstr("cannot create temporary file"),
                                HasSubstr("No such file or directory")));
    EXPECT_EQ(e.code().value(), ENOENT);
  }

  const fs::path path = file("f.bin"), elsewhere = file("elsewhere.bin");
  write_bytes(elsewhere, "untouched");
  fs::create_symlink(elsewhere, tmp_of(path));  // would redirect the write
  EXPECT_THROW(write_file_atomically(path, "x"), AtomicWriteError);
  EXPECT_EQ(read_bytes(elsewhere), "untouched");
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(AtomicFile, WriterLeavingAFailedStreamIsAFailure) {
  const fs::path path = file("f.bin");
  write_bytes(path, "old");
  EXPECT_THROW(write_file_atomically(path, [](std::ostream& out) { out.setstate(std::ios::failbit); }),
               AtomicWriteError);
  EXPECT_EQ(read_bytes(path), "old");
  EXPECT_FALSE(fs::exists(tmp_of(path)));
}

// ---------------------------------------------------------------------------
// Round trips and the byte layout.

TEST_F(CheckpointFormat, RoundTripIsBitExactForEveryTypeAndAwkwardValues) {
  const Checkpoint c = small_checkpoint();
  const fs::path path = file("c.ckpt");
  write_checkpoint(path, c);
  EXPECT_FALSE(fs::exists(tmp_of(path)));
  const Checkpoint r = read_checkpoint(path);
  expect_same(r, c);
  EXPECT_EQ(r.source, path);

  // Spelled out: NaN payloads (quiet and signaling), -0 and subnormals keep their bits.
  const auto& m = r.get<float>("static/means", {2, 3});
  EXPECT_EQ(bits(m[1]), 0x80000000u);
  EXPECT_EQ(bits(m[2]), bits(1e-45f));
  EXPECT_EQ(bits(m[5]), 0x7fc01234u);
  EXPECT_EQ(bits(r.get<float>("static/adam_m/means")[0]), 0xff800001u);
  EXPECT_EQ(bits(r.get<float>("static/adam_m/means")[1]), 0x7f800001u);
  EXPECT_EQ(r.get<std::uint64_t>("step_counter", {}), std::vector<std::uint64_t>{18446744073709551615u});
  EXPECT_EQ(r.array("empty").shape(), (CheckpointArray::Shape{0, 3}));
  EXPECT_EQ(r.metadata["config"]["tiny"].get<double>(), 4.9e-324);
  EXPECT_EQ(r.metadata["u64_max"].get<std::uint64_t>(), std::numeric_limits<std::uint64_t>::max());
}

TEST_F(CheckpointFormat, LibraryWritesExactlyTheDocumentedBytes) {
  const Checkpoint c = small_checkpoint();
  RawFile raw;
  raw.sections.push_back(raw_metadata(c.metadata.dump()));
  for (const auto& [name, a] : c.arrays) {  // the map's order is the name order
    std::string payload(a.byte_size(), '\0');
    if (!payload.empty()) std::memcpy(payload.data(), a.data(), payload.size());
    raw.sections.push_back({static_cast<std::uint8_t>(a.type()), name, a.shape(), payload.size(), payload});
  }
  write_checkpoint(file("c.ckpt"), c);
  EXPECT_EQ(read_bytes(file("c.ckpt")), raw.bytes());

  write_checkpoint(file("again.ckpt"), read_checkpoint(file("c.ckpt")));  // deterministic
  EXPECT_EQ(read_bytes(file("again.ckpt")), read_bytes(file("c.ckpt")));
}

TEST_F(CheckpointFormat, RngStateRestoresTheSameDraws) {
  std::mt19937_64 engine(20240607);
  std::normal_distribution<double> gauss;  // caches its second value: state of its own
  for (int i = 0; i < 12345; ++i) engine();
  (void)gauss(engine);
  Checkpoint c;
  c.metadata["rng"] = save_rng_state(engine);
  c.metadata["gauss"] = save_rng_state(gauss);
  write_checkpoint(file("rng.ckpt"), c);

  const Checkpoint r = read_checkpoint(file("rng.ckpt"));
  std::mt19937_64 restored;
  std::normal_distribution<double> restored_gauss;
  restore_rng_state(restored, r.metadata["rng"].get<std::string>());
  restore_rng_state(restored_gauss, r.metadata["gauss"].get<std::string>());
  EXPECT_EQ(restored, engine);
  for (int i = 0; i < 10000; ++i) ASSERT_EQ(restored(), engine()) << "draw " << i;
  for (int i = 0; i < 100; ++i)
    ASSERT_EQ(std::bit_cast<std::uint64_t>(restored_gauss(restored)),
              std::bit_cast<std::uint64_t>(gauss(engine)));
}

TEST(CheckpointRng, MalformedStateIsRejectedAndTheEngineKept) {
  std::mt19937_64 engine(7);
  const std::mt19937_64 before = engine;
  const std::string good = save_rng_state(engine);
  for (const std::string& bad : {std::string(), std::string("1 2 3"), good.substr(0, good.size() / 2),
                                 good + " 99", std::string("not a number")}) {
    EXPECT_THROW(restore_rng_state(engine, bad), CheckpointError) << bad.substr(0, 40);
    EXPECT_EQ(engine, before);
  }
}

TEST_F(CheckpointFormat, AccessorsNameTheFileTheArrayAndTheExpectation) {
  write_checkpoint(file("c.ckpt"), small_checkpoint());
  const Checkpoint r = read_checkpoint(file("c.ckpt"));
  const std::string prefix = file("c.ckpt").string() + ": array ";
  const auto message = [](const std::function<void()>& f) {
    try {
      f();
    } catch (const CheckpointError& e) {
      return std::string(e.what());
    }
    return std::string("(no exception)");
  };
  EXPECT_EQ(message([&] { r.get<float>("static/scales"); }), prefix + "'static/scales' is missing");
  EXPECT_EQ(message([&] { r.get<std::int32_t>("static/means"); }),
            prefix + "'static/means' holds float32, expected int32");
  EXPECT_EQ(message([&] { r.get<float>("static/means", {3, 2}); }),
            prefix + "'static/means' has shape [2, 3], expected [3, 2]");
  EXPECT_THAT(message([&] { Checkpoint().get<float>("x"); }), StartsWith("checkpoint: array 'x'"));
}

TEST(CheckpointArrays, InvariantsAreEnforcedWhenBuilding) {
  Checkpoint c;
  EXPECT_THROW(c.put<float>("a", {2, 3}, std::vector<float>(5)), std::invalid_argument);
  EXPECT_THROW(c.put<float>("has space", {1}, {1}), std::invalid_argument);
  EXPECT_THROW(c.put<float>("", {1}, {1}), std::invalid_argument);
  EXPECT_THROW(c.put<float>(std::string(256, 'a'), {1}, {1}), std::invalid_argument);
  EXPECT_THROW(c.put<float>("a", CheckpointArray::Shape(9, 1), {1}), std::invalid_argument);
  const std::uint64_t big = std::uint64_t{1} << 32;  // big^2 overflows the element count
  EXPECT_THROW(c.put<float>("a", {big, big}, {}), std::invalid_argument);
  c.put<float>("a", {1}, {1});
  c.put<std::uint8_t>("a", {2}, {1, 2});  // replaces
  EXPECT_EQ(c.array("a").type(), ArrayType::UInt8);

  CheckpointArray x({2}, std::vector<float>{0.0f, 1}), y({2}, std::vector<float>{-0.0f, 1});
  EXPECT_FALSE(x == y) << "equality is bitwise";
  EXPECT_FALSE(x == CheckpointArray({1, 2}, std::vector<float>{0.0f, 1}));
}

TEST_F(CheckpointFormat, WriterRefusesUnrepresentableInputWithoutTouchingTheFile) {
  const fs::path path = file("c.ckpt");
  write_checkpoint(path, small_checkpoint());
  const std::string before = read_bytes(path);

  Checkpoint nan_meta;
  nan_meta.metadata["loss"] = std::nan("");
  EXPECT_THAT(write_error(path, nan_meta), HasSubstr("does not survive a JSON round trip"));
  Checkpoint not_object;
  not_object.metadata = nlohmann::json::array({1, 2});
  EXPECT_THAT(write_error(path, not_object), HasSubstr("metadata must be a JSON object, not array"));
  Checkpoint bad_utf8;
  bad_utf8.metadata["name"] = std::string("\xff\xfe");
  EXPECT_THAT(write_error(path, bad_utf8), HasSubstr("metadata cannot be written as JSON"));
  Checkpoint bad_name;
  bad_name.arrays.emplace("has space", CheckpointArray());  // bypassing put()
  EXPECT_THAT(write_error(path, bad_name), HasSubstr("invalid array name 'has space'"));
  Checkpoint future;
  future.format_version = 2;
  EXPECT_THAT(write_error(path, future), HasSubstr("cannot write format version 2"));

  EXPECT_EQ(read_bytes(path), before);
  EXPECT_FALSE(fs::exists(tmp_of(path)));
}

// ---------------------------------------------------------------------------
// Corruption: each kind gives one clear error naming the file.

TEST_F(CheckpointCorruption, FileLevelProblems) {
  EXPECT_THAT(read_error(file("missing.ckpt")), HasSubstr("file does not exist"));
  EXPECT_THAT(read_error(dir_), HasSubstr("not a regular file"));

  write_bytes(file("empty.ckpt"), "");
  EXPECT_THAT(read_error(file("empty.ckpt")),
              HasSubstr("truncated: 0 bytes, shorter than the 24-byte file header"));

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
  EXPECT_THAT(error_for("size.ckpt", f),
              HasSubstr("section 'a': shape [2, 3] of 4-byte elements needs 24 bytes, "
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
  EXPECT_THAT(error_for("noname.ckpt", f),
              HasSubstr("section #1 (offset 70): name length 0 is not in 1..255"));
  f.sections[1].name = "a b";
  EXPECT_THAT(error_for("space.ckpt", f), HasSubstr("invalid section name"));
  f.sections[1].name = "b";
  EXPECT_THAT(error_for("dup.ckpt", f), HasSubstr("duplicate array 'b'"));

  std::string flipped = raw_valid().bytes();
  flipped[70 + 13] ^= 0x10;  // a dims byte of section #1
  write_bytes(file("hcrc.ckpt"), flipped);
  EXPECT_THAT(read_error(file("hcrc.ckpt")),
              HasSubstr("section #1 (offset 70): header checksum mismatch (stored 0x"));
}

TEST_F(CheckpointCorruption, MetadataProblems) {
  const auto error_for = [&](const std::string& name, const RawFile& f) {
    write_bytes(file(name), f.bytes());
    return read_error(file(name));
  };
  RawFile f = raw_valid();
  f.sections.erase(f.sections.begin());
  EXPECT_THAT(error_for("nometa.ckpt", f),
              HasSubstr("the first section must be the metadata, found 'a' of type 1"));
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
    ASSERT_THAT(read_error(cut), HasSubstr("truncated"))
        << "prefix of " << len << " of " << bytes.size() << " bytes";
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
    ASSERT_TRUE(read_bytes(path) == old_bytes)
        << "the old checkpoint was modified or replaced by a partial file";
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
  for (U limit : {U{0}, U{1}, U{23}, U{24}, U{100}, total / 4, total / 2, 3 * total / 4, total - 4,
                  total - 1}) {
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
      ASSERT_TRUE(read_bytes(scene.path) == scene.new_bytes)
          << "renamed, so it must be the complete new file";
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
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;)
    message.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  const int status = wait_for(pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_THAT(message, AllOf(StartsWith(scene.path.string() + ": write to temporary file"),
                             HasSubstr("File too large")));
  scene.expect_old_intact();
  EXPECT_FALSE(fs::exists(tmp_of(scene.path)));
}

}  // namespace
}  // namespace desplat
