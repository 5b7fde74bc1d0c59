// Checkpoints and atomic file replacement: bit-exact round trips, the documented byte layout
// (checked against the test's own encoder), one clear CheckpointError per kind of corruption,
// and crash safety: a writer killed at many moments of a ~50 MB write, or failing mid-stream,
// leaves the previous checkpoint byte-identical and loadable.
#include <gtest/gtest.h>

#include "support/checkpoint_fixtures.hpp"

namespace desplat {
namespace {
using namespace checkpoint_test;

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
    ASSERT_EQ(std::bit_cast<std::uint64_t>(restored_gauss(restored)), std::bit_cast<std::uint64_t>(gauss(engine)));
}

TEST(CheckpointRng, MalformedStateIsRejectedAndTheEngineKept) {
  std::mt19937_64 engine(7);
  const std::mt19937_64 before = engine;
  const std::string good = save_rng_state(engine);
  for (const std::string& bad : {std::string(), std::string("1 2 3"), good.substr(0, good.size() / 2), good + " 99",
                                 std::string("not a number")}) {
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
  EXPECT_EQ(message([&] {
              r.get<float>("static/means", {3, 2});
            }),
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

}  // namespace
}  // namespace desplat
