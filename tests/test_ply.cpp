// 3DGS PLY export/import: lossless round trips, the byte layout parsed by hand,
// files from other tools, and one clear PlyError per kind of bad input.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "desplat/io/ply.hpp"
#include "support/temp_dir.hpp"

namespace desplat {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

// ---------------------------------------------------------------------------
// Helpers (the test's own encoding, independent of the library's).

class Ply : public ::testing::Test {
 protected:
  fs::path file(const std::string& name) const { return dir_ / name; }

  desplat::testing::TempDir tmp_{"ply"};
  const fs::path dir_ = tmp_.path();
};

std::string le_bytes(const std::vector<float>& values) {
  std::string out;
  for (float v : values) {
    const auto u = std::bit_cast<std::uint32_t>(v);
    for (int b = 0; b < 4; ++b) out += static_cast<char>((u >> (8 * b)) & 0xff);
  }
  return out;
}

float le_float_at(const std::string& bytes, std::size_t offset) {
  std::uint32_t u = 0;
  for (int b = 0; b < 4; ++b) u |= std::uint32_t{static_cast<unsigned char>(bytes[offset + b])} << (8 * b);
  return std::bit_cast<float>(u);
}

void write_bytes(const fs::path& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::uint32_t bits(float v) { return std::bit_cast<std::uint32_t>(v); }

void expect_same_bits(const std::vector<float>& got, const std::vector<float>& want, const char* name) {
  ASSERT_EQ(got.size(), want.size()) << name;
  for (std::size_t i = 0; i < want.size(); ++i)
    ASSERT_EQ(bits(got[i]), bits(want[i])) << name << "[" << i << "]: got " << got[i] << ", want " << want[i];
}

GaussianSet random_gaussians(std::size_t n, int degree, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-3, 3);
  GaussianSet g;
  g.sh_degree = degree;
  g.resize(n);
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.colors})
    for (float& v : *a) v = u(rng);
  return g;
}

// Values a careless conversion would not carry through bit for bit.
void plant_awkward_values(GaussianSet& g) {
  g.means[0] = -0.0f;
  g.means[1] = 1e-40f;  // subnormal
  g.means[2] = FLT_MAX;
  g.log_scales[0] = -FLT_MAX;
  g.quats[1] = FLT_MIN;
  g.opacity_logits[0] = std::nextafter(1.0f, 2.0f);
  g.colors.back() = -0.0f;
}

// Standard 3DGS property names for `rest` f_rest values, spelled out from the spec.
std::vector<std::string> standard_props(int rest) {
  std::vector<std::string> p = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int j = 0; j < rest; ++j) p.push_back("f_rest_" + std::to_string(j));
  for (const char* s : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) p.push_back(s);
  return p;
}

// A hand-built PLY; each field can be broken on purpose. A property entry containing
// a space is a full "<type> <name>" (or list) spec, otherwise it is a float.
struct FakePly {
  std::string format = "binary_little_endian 1.0";
  std::vector<std::string> before;  // header lines before the vertex element
  std::string vertex_count = "2";
  std::vector<std::string> props = standard_props(0);
  std::vector<std::string> after;  // header lines after the vertex properties
  std::string newline = "\n";

  std::string header() const {
    std::string h = "ply" + newline + "format " + format + newline;
    for (const auto& l : before) h += l + newline;
    h += "element vertex " + vertex_count + newline;
    for (const auto& p : props) h += "property " + (p.find(' ') == std::string::npos ? "float " + p : p) + newline;
    for (const auto& l : after) h += l + newline;
    return h + "end_header" + newline;
  }
  // n records of plausible values (all 0.25, finite).
  std::string body(std::size_t n) const { return le_bytes(std::vector<float>(n * props.size(), 0.25f)); }
  std::string bytes() const { return header() + body(std::stoul(vertex_count)); }
};

// The PlyError message from reading `path`; any other exception fails the test.
std::string read_error(const fs::path& path) {
  try {
    read_gaussian_ply(path);
  } catch (const PlyError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

std::string write_error(const fs::path& path, const GaussianSet& g, const WorldNormalization& norm = {}) {
  try {
    write_gaussian_ply(path, g, norm);
  } catch (const PlyError& e) {
    EXPECT_THAT(e.what(), StartsWith(path.string() + ": "));
    return e.what();
  }
  return "(no exception)";
}

// ---------------------------------------------------------------------------
// Round trips.

TEST_F(Ply, RoundTripIsBitExactForEverySHDegree) {
  for (int degree = 0; degree <= 3; ++degree) {
    SCOPED_TRACE("SH degree " + std::to_string(degree));
    GaussianSet g = random_gaussians(37, degree, 100 + degree);
    plant_awkward_values(g);
    const fs::path path = file("deg" + std::to_string(degree) + ".ply");
    write_gaussian_ply(path, g);
    EXPECT_FALSE(fs::exists(fs::path(path) += ".tmp")) << "temporary left behind";

    const GaussianSet r = read_gaussian_ply(path);
    EXPECT_EQ(r.color_mode, ColorMode::SphericalHarmonics);
    EXPECT_EQ(r.sh_degree, degree);
    expect_same_bits(r.means, g.means, "means");
    expect_same_bits(r.log_scales, g.log_scales, "log_scales");
    expect_same_bits(r.quats, g.quats, "quats");
    expect_same_bits(r.opacity_logits, g.opacity_logits, "opacity_logits");
    expect_same_bits(r.colors, g.colors, "colors");
  }
}

TEST_F(Ply, RoundTripOfAnEmptySetKeepsTheDegree) {
  GaussianSet g;
  g.sh_degree = 2;
  write_gaussian_ply(file("empty.ply"), g);
  const GaussianSet r = read_gaussian_ply(file("empty.ply"));
  EXPECT_EQ(r.size(), 0u);
  EXPECT_EQ(r.sh_degree, 2);
  EXPECT_TRUE(r.colors.empty());
}

// The writer computes in double and rounds once, so each value must be within half a
// float ulp of the double-precision result (plus 1e-9 relative for the test's own
// double rounding). A float-precision path misses this by up to ~1.5 ulp here: the
// center is large and not representable in float.
void expect_correctly_rounded(float got, double exact, const std::string& what) {
  const float f = static_cast<float>(exact);
  const double gap = std::max(double{std::nextafter(f, INFINITY)} - f, double{f} - std::nextafter(f, -INFINITY));
  EXPECT_LE(std::abs(double{got} - exact), 0.5 * gap + 1e-9 * std::abs(exact))
      << what << ": got " << got << ", exact " << exact;
}

TEST_F(Ply, NormalizationIsUndoneInDoublePrecision) {
  GaussianSet g = random_gaussians(200, 3, 7);
  g.means[0] = g.means[1] = g.means[2] = 0;  // the normalized origin maps to the center
  g.log_scales[0] = 0;
  WorldNormalization norm;
  norm.center = {103.7, -48.21, 7301.3};
  norm.scale = 0.0371;
  write_gaussian_ply(file("n.ply"), g, norm);
  const GaussianSet r = read_gaussian_ply(file("n.ply"));

  for (int a = 0; a < 3; ++a) EXPECT_EQ(r.means[a], static_cast<float>(norm.center[a]));
  EXPECT_EQ(r.log_scales[0], static_cast<float>(-std::log(0.0371)));
  for (std::size_t i = 0; i < g.means.size(); ++i)
    expect_correctly_rounded(r.means[i], double{g.means[i]} / norm.scale + norm.center[i % 3],
                             "mean " + std::to_string(i));
  for (std::size_t i = 0; i < g.log_scales.size(); ++i)
    expect_correctly_rounded(r.log_scales[i], double{g.log_scales[i]} - std::log(norm.scale),
                             "log_scale " + std::to_string(i));
  expect_same_bits(r.quats, g.quats, "quats");
  expect_same_bits(r.opacity_logits, g.opacity_logits, "opacity_logits");
  expect_same_bits(r.colors, g.colors, "colors");
}

TEST_F(Ply, WriteReplacesAtomicallyAndAFailedWriteLeavesTheOldFile) {
  const fs::path path = file("a.ply");
  write_bytes(path, "old contents");
  GaussianSet g = random_gaussians(5, 1, 3);
  write_gaussian_ply(path, g);
  EXPECT_EQ(read_gaussian_ply(path).size(), 5u);

  const std::string before = read_bytes(path);
  g.means.back() = NAN;  // fails after the temporary file was opened
  EXPECT_THAT(write_error(path, g), AllOf(HasSubstr("Gaussian 4"), HasSubstr("'z'"), HasSubstr("NaN")));
  EXPECT_EQ(read_bytes(path), before);
  EXPECT_FALSE(fs::exists(fs::path(path) += ".tmp"));
}

// ---------------------------------------------------------------------------
// Byte layout, decoded by hand.

TEST_F(Ply, ByteLayoutIsTheStandardOrderWithChannelMajorRest) {
  GaussianSet g;
  g.sh_degree = 1;
  g.resize(2);
  g.means = {1.5f, -2.25f, 3.0f, 10.5f, 20.25f, -30.0f};
  g.log_scales = {-1.5f, -2.5f, -3.5f, -4.5f, -5.5f, -6.5f};
  g.quats = {0.5f, 0.25f, 0.125f, 0.0625f, 1, 2, 3, 4};
  g.opacity_logits = {0.75f, -0.75f};
  for (int i = 0; i < 2; ++i)
    for (int k = 0; k < 4; ++k)
      for (int c = 0; c < 3; ++c) g.colors[12 * i + 3 * k + c] = 100.0f * (i + 1) + 10.0f * k + c;
  const fs::path path = file("layout.ply");
  write_gaussian_ply(path, g);
  const std::string bytes = read_bytes(path);

  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
      "property float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n"
      "property float f_rest_0\nproperty float f_rest_1\nproperty float f_rest_2\n"
      "property float f_rest_3\nproperty float f_rest_4\nproperty float f_rest_5\n"
      "property float f_rest_6\nproperty float f_rest_7\nproperty float f_rest_8\n"
      "property float opacity\n"
      "property float scale_0\nproperty float scale_1\nproperty float scale_2\n"
      "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
      "end_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  constexpr std::size_t kRecord = 26 * 4;
  ASSERT_EQ(bytes.size(), header.size() + 2 * kRecord);

  // f_rest: R of coefficients 1..3, then G, then B; normals zero.
  const std::vector<std::vector<float>> want = {
      {1.5f, -2.25f, 3,   0,   0,   0,     100,   101,   102,   110,  120,   130,    111,
       121,  131,    112, 122, 132, 0.75f, -1.5f, -2.5f, -3.5f, 0.5f, 0.25f, 0.125f, 0.0625f},
      {10.5f, 20.25f, -30, 0,   0,   0,      200,   201,   202,   210, 220, 230, 211,
       221,   231,    212, 222, 232, -0.75f, -4.5f, -5.5f, -6.5f, 1,   2,   3,   4}};
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t p = 0; p < 26; ++p)
      EXPECT_EQ(le_float_at(bytes, header.size() + i * kRecord + 4 * p), want[i][p])
          << "vertex " << i << " property #" << p;
  // f_rest_3 = first G coefficient (colors[1][1][1] = 211) at float 12 of record 1.
  EXPECT_EQ(le_float_at(bytes, header.size() + kRecord + 4 * 12), 211.0f);
}

TEST_F(Ply, Degree3HasFortyFiveRestValuesPerRecord) {
  GaussianSet g;
  g.sh_degree = 3;
  g.resize(1);
  for (int k = 0; k < 16; ++k)
    for (int c = 0; c < 3; ++c) g.colors[3 * k + c] = 10.0f * k + c;
  const fs::path path = file("d3.ply");
  write_gaussian_ply(path, g);
  const std::string bytes = read_bytes(path);
  const std::size_t body = bytes.find("end_header\n") + 11;
  EXPECT_THAT(bytes.substr(0, body), HasSubstr("property float f_rest_44\nproperty float opacity\n"));
  EXPECT_THAT(bytes.substr(0, body), Not(HasSubstr("f_rest_45")));
  ASSERT_EQ(bytes.size() - body, 62u * 4);

  auto rest = [&](int j) { return le_float_at(bytes, body + 4 * (9 + j)); };
  EXPECT_EQ(rest(0), 10.0f);    // R, coefficient 1
  EXPECT_EQ(rest(14), 150.0f);  // R, coefficient 15
  EXPECT_EQ(rest(15), 11.0f);   // G, coefficient 1
  EXPECT_EQ(rest(30), 12.0f);   // B, coefficient 1
  EXPECT_EQ(rest(44), 152.0f);  // B, coefficient 15
}

// ---------------------------------------------------------------------------
// Files written by other tools.

TEST_F(Ply, ReadsOtherPropertyOrderWithNormalsAndNoRest) {
  FakePly f;
  f.before = {"comment exported by SomeViewer 2.1"};
  f.props = {"opacity", "rot_3",  "rot_2", "rot_1", "rot_0", "scale_2", "scale_1", "scale_0", "f_dc_1",
             "f_dc_2",  "f_dc_0", "nx",    "ny",    "nz",    "z",       "y",       "x"};
  const std::vector<float> values = {-1, 0.4f, 0.3f, 0.2f, 0.1f, -3,  -2,  -1, 0.5f, 0.6f, 0.4f, 9,
                                     9,  9,    3,    2,    1,    2,   4,   3,  2,    1,    -6,   -5,
                                     -4, 1.5f, 1.6f, 1.4f, NAN,  NAN, NAN, 6,  5,    4};  // normals ignored
  write_bytes(file("foreign.ply"), f.header() + le_bytes(values));

  const GaussianSet r = read_gaussian_ply(file("foreign.ply"));
  EXPECT_EQ(r.sh_degree, 0);
  EXPECT_EQ(r.means, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(r.log_scales, (std::vector<float>{-1, -2, -3, -4, -5, -6}));
  EXPECT_EQ(r.quats, (std::vector<float>{0.1f, 0.2f, 0.3f, 0.4f, 1, 2, 3, 4}));
  EXPECT_EQ(r.opacity_logits, (std::vector<float>{-1, 2}));
  EXPECT_EQ(r.colors, (std::vector<float>{0.4f, 0.5f, 0.6f, 1.4f, 1.5f, 1.6f}));
}

TEST_F(Ply, ReadsScrambledRestCrLfFloat32AndAnEmptyExtraElement) {
  FakePly f;
  f.newline = "\r\n";
  f.vertex_count = "1";
  f.props = {"x", "y", "float32 z", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int j = 8; j >= 0; --j) f.props.push_back("f_rest_" + std::to_string(j));
  for (const char* p : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    f.props.push_back(p);
  f.after = {"obj_info generator x", "element face 0", "property list uchar int vertex_indices"};
  // f_rest_j holds the value j.
  const std::vector<float> values = {1, 2, 3, 0.1f, 0.2f, 0.3f, 8,  7,    6,    5, 4, 3,
                                     2, 1, 0, -1,   -2,   -3,   -4, 0.6f, 0.8f, 0, 0};
  write_bytes(file("crlf.ply"), f.header() + le_bytes(values));

  const GaussianSet r = read_gaussian_ply(file("crlf.ply"));
  EXPECT_EQ(r.sh_degree, 1);
  // Coefficient k, channel c comes from f_rest_{3c + k - 1}.
  EXPECT_EQ(r.colors, (std::vector<float>{0.1f, 0.2f, 0.3f, 0, 3, 6, 1, 4, 7, 2, 5, 8}));
  EXPECT_EQ(r.means, (std::vector<float>{1, 2, 3}));
  EXPECT_EQ(r.log_scales, (std::vector<float>{-2, -3, -4}));
  EXPECT_EQ(r.quats, (std::vector<float>{0.6f, 0.8f, 0, 0}));
  EXPECT_EQ(r.opacity_logits, (std::vector<float>{-1}));
}

// ---------------------------------------------------------------------------
// Bad input: one clear PlyError each.

TEST_F(Ply, SanityTheBaseFakeFileIsValid) {
  write_bytes(file("ok.ply"), FakePly{}.bytes());
  EXPECT_EQ(read_gaussian_ply(file("ok.ply")).size(), 2u);
}

TEST_F(Ply, MissingFile) { EXPECT_THAT(read_error(file("nope.ply")), HasSubstr("does not exist")); }

TEST_F(Ply, Directory) { EXPECT_THAT(read_error(dir_), HasSubstr("not a regular file")); }

TEST_F(Ply, EmptyFile) {
  write_bytes(file("e.ply"), "");
  EXPECT_THAT(read_error(file("e.ply")), HasSubstr("not a PLY file (empty)"));
}

TEST_F(Ply, NotAPly) {
  write_bytes(file("x.ply"), "solid cube\nfacet normal 0 0 1\n");
  EXPECT_THAT(read_error(file("x.ply")), HasSubstr("not a PLY file"));
}

TEST_F(Ply, AsciiFormat) {
  FakePly f;
  f.format = "ascii 1.0";
  write_bytes(file("a.ply"), f.header());
  EXPECT_THAT(read_error(file("a.ply")),
              AllOf(HasSubstr("ascii PLY is not supported"), HasSubstr("binary_little_endian 1.0")));
}

TEST_F(Ply, BigEndianFormat) {
  FakePly f;
  f.format = "binary_big_endian 1.0";
  write_bytes(file("b.ply"), f.bytes());
  EXPECT_THAT(read_error(file("b.ply")), AllOf(HasSubstr("big-endian"), HasSubstr("only binary_little_endian 1.0")));
}

TEST_F(Ply, UnsupportedVersion) {
  FakePly f;
  f.format = "binary_little_endian 2.0";
  write_bytes(file("v.ply"), f.bytes());
  EXPECT_THAT(read_error(file("v.ply")), AllOf(HasSubstr("'format binary_little_endian 2.0'"), HasSubstr("version")));
}

TEST_F(Ply, NoVertexElement) {
  write_bytes(file("nv.ply"),
              "ply\nformat binary_little_endian 1.0\nelement face 0\n"
              "property list uchar int vertex_indices\nend_header\n");
  EXPECT_THAT(read_error(file("nv.ply")), HasSubstr("no vertex element"));
}

TEST_F(Ply, MissingRequiredProperty) {
  FakePly f;
  f.props.pop_back();  // rot_3
  write_bytes(file("m.ply"), f.bytes());
  EXPECT_THAT(read_error(file("m.ply")), HasSubstr("missing required vertex property 'rot_3'"));
}

TEST_F(Ply, UnknownPropertyIsNotDropped) {
  FakePly f;
  f.props.push_back("semantic_label");
  write_bytes(file("u.ply"), f.bytes());
  EXPECT_THAT(read_error(file("u.ply")), HasSubstr("unknown vertex property 'semantic_label'"));
}

TEST_F(Ply, DuplicateProperty) {
  FakePly f;
  f.props.push_back("opacity");
  write_bytes(file("d.ply"), f.bytes());
  EXPECT_THAT(read_error(file("d.ply")), HasSubstr("duplicate vertex property 'opacity'"));
}

TEST_F(Ply, NonFloatPropertyType) {
  FakePly f;
  f.props[0] = "double x";
  write_bytes(file("t.ply"), f.bytes());
  EXPECT_THAT(read_error(file("t.ply")), HasSubstr("'x' has type 'double'; only float (float32) is supported"));

  f = FakePly{};
  f.props.push_back("list uchar float extra");
  write_bytes(file("l.ply"), f.header());
  EXPECT_THAT(read_error(file("l.ply")), HasSubstr("'extra' is a list"));
}

TEST_F(Ply, WrongRestCount) {
  FakePly f;
  f.props = standard_props(10);
  write_bytes(file("r.ply"), f.bytes());
  EXPECT_THAT(read_error(file("r.ply")), HasSubstr("has 10 f_rest properties; expected 0, 9, 24 or 45"));
}

TEST_F(Ply, RestIndicesWithAGap) {
  FakePly f;
  f.props = standard_props(9);
  for (auto& p : f.props)
    if (p == "f_rest_8") p = "f_rest_9";
  write_bytes(file("g.ply"), f.bytes());
  EXPECT_THAT(read_error(file("g.ply")), HasSubstr("missing required vertex property 'f_rest_8'"));
}

TEST_F(Ply, ElementWithDataBeforeVertex) {
  FakePly f;
  f.before = {"element camera 1", "property float fx"};
  write_bytes(file("c.ply"), f.header() + le_bytes({500}) + f.body(2));
  EXPECT_THAT(read_error(file("c.ply")),
              AllOf(HasSubstr("element 'camera' has 1 entries"), HasSubstr("only a vertex element is supported")));
}

TEST_F(Ply, ElementWithDataAfterVertex) {
  FakePly f;
  f.after = {"element face 1", "property list uchar int vertex_indices"};
  write_bytes(file("f.ply"), f.bytes() + std::string("\x03\0\0\0\0\x01\0\0\0\x02\0\0\0", 13));
  EXPECT_THAT(read_error(file("f.ply")), HasSubstr("element 'face' has 1 entries"));
}

TEST_F(Ply, TwoVertexElements) {
  FakePly f;
  f.after = {"element vertex 0", "property float x"};
  write_bytes(file("2v.ply"), f.bytes());
  EXPECT_THAT(read_error(file("2v.ply")), HasSubstr("more than one vertex element"));
}

TEST_F(Ply, HeaderWithoutEndHeader) {
  write_bytes(file("h.ply"), "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n");
  EXPECT_THAT(read_error(file("h.ply")), HasSubstr("header has no end_header line"));
}

TEST_F(Ply, HeaderScanIsBoundedOnALargeFile) {
  // 3 MiB of comment lines: the reader must stop after its 1 MiB header bound.
  std::string big = "ply\nformat binary_little_endian 1.0\n";
  while (big.size() < (std::size_t{3} << 20)) big += "comment padding padding padding padding padding\n";
  write_bytes(file("big.ply"), big);
  EXPECT_THAT(read_error(file("big.ply")), HasSubstr("no end_header line within the first 1048576 bytes"));
}

TEST_F(Ply, UnexpectedHeaderLine) {
  FakePly f;
  f.before = {"elemnt vertex 2"};
  write_bytes(file("k.ply"), f.bytes());
  EXPECT_THAT(read_error(file("k.ply")), AllOf(HasSubstr("header line 3"), HasSubstr("unexpected keyword")));
}

TEST_F(Ply, TruncatedBody) {
  FakePly f;
  const std::string bytes = f.bytes();
  write_bytes(file("tr.ply"), bytes.substr(0, bytes.size() - 1));
  EXPECT_THAT(read_error(file("tr.ply")),
              AllOf(HasSubstr("truncated"), HasSubstr("declares 2 vertices of 68 bytes"), HasSubstr("room for 1")));
}

TEST_F(Ply, TrailingBytes) {
  write_bytes(file("tb.ply"), FakePly{}.bytes() + "junk");
  EXPECT_THAT(read_error(file("tb.ply")), HasSubstr("4 trailing bytes after the last of 2 vertex records"));
}

TEST_F(Ply, NaNAndInfAreNamed) {
  FakePly f;
  std::vector<float> values(2 * f.props.size(), 0.25f);
  values[f.props.size() + 9] = NAN;  // vertex 1, property #9 = opacity
  write_bytes(file("nan.ply"), f.header() + le_bytes(values));
  EXPECT_THAT(read_error(file("nan.ply")), HasSubstr("vertex 1 property 'opacity' is NaN"));

  f.props = standard_props(9);
  values.assign(2 * f.props.size(), 0.25f);
  values[9 + 4] = -INFINITY;  // vertex 0, f_rest_4
  write_bytes(file("inf.ply"), f.header() + le_bytes(values));
  EXPECT_THAT(read_error(file("inf.ply")), HasSubstr("vertex 0 property 'f_rest_4' is -Inf"));
}

TEST_F(Ply, HugeVertexCountIsRejectedBeforeAllocating) {
  // If the reader allocated first, these would throw bad_alloc/length_error (or
  // exhaust memory) instead of PlyError.
  FakePly f;
  f.vertex_count = std::to_string(std::numeric_limits<std::uint64_t>::max());
  write_bytes(file("h1.ply"), f.header() + f.body(2));
  EXPECT_THAT(read_error(file("h1.ply")), AllOf(HasSubstr("truncated"), HasSubstr(f.vertex_count)));

  // 271275648142787524 × 68 bytes wraps to 16 in 64-bit arithmetic: a 16-byte body
  // must not pass a naive "count × record == body size" check.
  f.vertex_count = "271275648142787524";
  write_bytes(file("h2.ply"), f.header() + std::string(16, '\0'));
  EXPECT_THAT(read_error(file("h2.ply")), AllOf(HasSubstr("truncated"), HasSubstr("room for 0")));
}

TEST_F(Ply, VertexCountThatIsNotACount) {
  for (const char* count : {"-1", "2.0", "18446744073709551616", "many"}) {
    FakePly f;
    f.vertex_count = count;
    write_bytes(file("c.ply"), f.header() + f.body(2));
    EXPECT_THAT(read_error(file("c.ply")), HasSubstr("element count '" + std::string(count) + "'"));
  }
}

// ---------------------------------------------------------------------------
// Writer errors.

TEST_F(Ply, RgbModeCannotBeExported) {
  GaussianSet g;
  g.color_mode = ColorMode::RGB;
  g.resize(3);
  EXPECT_THAT(write_error(file("rgb.ply"), g), HasSubstr("cannot export RGB-mode Gaussians"));
  EXPECT_FALSE(fs::exists(file("rgb.ply")));
}

TEST_F(Ply, InconsistentArraysCannotBeExported) {
  GaussianSet g = random_gaussians(4, 1, 9);
  g.colors.pop_back();
  EXPECT_THAT(write_error(file("i.ply"), g), HasSubstr("colors has 47 values, expected 48"));
}

TEST_F(Ply, OverflowInTheOriginalFrameIsRejected) {
  GaussianSet g = random_gaussians(3, 0, 1);
  g.means[4] = 1e30f;
  WorldNormalization norm;
  norm.scale = 1e-20;  // 1e30 / 1e-20 does not fit in a float
  EXPECT_THAT(write_error(file("o.ply"), g, norm), HasSubstr("Gaussian 1 property 'y' is +Inf in the original frame"));
  norm.scale = 0;
  EXPECT_THAT(write_error(file("o.ply"), g, norm), HasSubstr("scale must be positive and finite"));
}

TEST_F(Ply, UnwritableLocation) {
  EXPECT_THAT(write_error(file("no_such_dir") / "g.ply", random_gaussians(2, 0, 1)), HasSubstr("cannot create"));
}

}  // namespace
}  // namespace desplat
