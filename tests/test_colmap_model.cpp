// COLMAP sparse-model I/O against the real fox capture, the real `colmap` executable
// (model_converter in both directions), exact round trips of every camera model, and one
// test per kind of bad input.
//
// Expected values come from outside our code: the fox numbers are copied from the
// cameras/images/points3D.txt that `colmap model_converter` writes for
// /work/shared/data/fox/sparse/0 (17 significant digits, so the literals below are the exact
// doubles), file sizes come from the documented byte layout, and corrupt files are made by
// patching bytes at documented offsets.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "desplat/io/colmap.hpp"

namespace fs = std::filesystem;
using namespace desplat::colmap;

namespace {

const fs::path kFoxDir = "/work/shared/data/fox/sparse/0";

// ---- Small file helpers -------------------------------------------------------------------

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Replaces the file by unlinking it first: truncating an existing file makes ext4 flush it to
// disk on close (auto_da_alloc), which made the corruption sweep take seconds instead of ms.
void spit(const fs::path& path, const std::string& bytes) {
  fs::remove(path);
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

template <class T>
void patch(std::string& bytes, size_t offset, T value) {
  ASSERT_LE(offset + sizeof(T), bytes.size());
  std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

template <class T>
T peek(const std::string& bytes, size_t offset) {
  T value{};
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

// Record start offsets in images.bin / points3D.bin, walked with the documented layout
// (independent of the library's reader).
std::vector<size_t> image_records(const std::string& bin) {
  std::vector<size_t> starts;
  size_t pos = 8;
  for (uint64_t i = 0, n = peek<uint64_t>(bin, 0); i < n; ++i) {
    starts.push_back(pos);
    const size_t name_end = bin.find('\0', pos + 64);
    pos = name_end + 1 + 8 + 24 * peek<uint64_t>(bin, name_end + 1);
  }
  return starts;
}

std::vector<size_t> point_records(const std::string& bin) {
  std::vector<size_t> starts;
  size_t pos = 8;
  for (uint64_t i = 0, n = peek<uint64_t>(bin, 0); i < n; ++i) {
    starts.push_back(pos);
    pos += 51 + 8 * peek<uint64_t>(bin, pos + 43);
  }
  return starts;
}

// A fresh directory, removed afterwards; unique per process, test and instance.
class TempDir {
 public:
  TempDir() {
    static int instances = 0;
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("desplat_colmap_" + std::to_string(::getpid()) + "_" + test->test_suite_name() +
             "_" + test->name() + "_" + std::to_string(instances++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }
  fs::path operator/(const char* sub) const { return path_ / sub; }

 private:
  fs::path path_;
};

// Copies fox's three .bin files into `dir` so a test can corrupt them.
fs::path copy_fox(const fs::path& dir) {
  fs::create_directories(dir);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    fs::remove(dir / f);  // see spit()
    fs::copy_file(kFoxDir / f, dir / f);
  }
  return dir;
}

// The ColmapError message `f` throws; a test failure if it throws nothing.
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ColmapError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a ColmapError, none was thrown";
  return "";
}

// Checks that reading fails with a message naming `file` and containing every fragment.
void expect_error(const std::function<void()>& f, const fs::path& file,
                  std::initializer_list<std::string_view> fragments) {
  const std::string msg = error_of(f);
  EXPECT_NE(msg.find(file.string()), std::string::npos) << "message lacks the file: " << msg;
  for (std::string_view frag : fragments)
    EXPECT_NE(msg.find(frag), std::string::npos) << "message lacks '" << frag << "': " << msg;
}

// ---- Model comparison (doubles bit for bit) -----------------------------------------------

bool same_bits(double a, double b) {
  return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
}

template <size_t N>
bool same_bits(const std::array<double, N>& a, const std::array<double, N>& b) {
  for (size_t k = 0; k < N; ++k)
    if (!same_bits(a[k], b[k])) return false;
  return true;
}

::testing::AssertionResult identical(const Model& a, const Model& b) {
  using ::testing::AssertionFailure;
  if (a.cameras.size() != b.cameras.size() || a.images.size() != b.images.size() ||
      a.points.size() != b.points.size())
    return AssertionFailure() << "sizes differ: cameras " << a.cameras.size() << "/"
                              << b.cameras.size() << ", images " << a.images.size() << "/"
                              << b.images.size() << ", points " << a.points.size() << "/"
                              << b.points.size();
  for (auto ia = a.cameras.begin(), ib = b.cameras.begin(); ia != a.cameras.end(); ++ia, ++ib) {
    const Camera &x = ia->second, &y = ib->second;
    bool same = ia->first == ib->first && x.id == y.id && x.model == y.model &&
                x.width == y.width && x.height == y.height && x.params.size() == y.params.size();
    for (size_t k = 0; same && k < x.params.size(); ++k) same = same_bits(x.params[k], y.params[k]);
    if (!same) return AssertionFailure() << "camera " << ia->first << " differs";
  }
  for (auto ia = a.images.begin(), ib = b.images.begin(); ia != a.images.end(); ++ia, ++ib) {
    const Image &x = ia->second, &y = ib->second;
    bool same = ia->first == ib->first && x.id == y.id && same_bits(x.qvec_wxyz, y.qvec_wxyz) &&
                same_bits(x.tvec, y.tvec) && x.camera_id == y.camera_id && x.name == y.name &&
                x.points2d.size() == y.points2d.size();
    if (!same) return AssertionFailure() << "image " << ia->first << " header differs";
    for (size_t k = 0; k < x.points2d.size(); ++k) {
      const Observation &p = x.points2d[k], &q = y.points2d[k];
      if (!same_bits(p.x, q.x) || !same_bits(p.y, q.y) || p.point3d_id != q.point3d_id)
        return AssertionFailure() << "image " << ia->first << " points2D[" << k << "] differs";
    }
  }
  for (auto ia = a.points.begin(), ib = b.points.begin(); ia != a.points.end(); ++ia, ++ib) {
    const Point3D &x = ia->second, &y = ib->second;
    if (ia->first != ib->first || x.id != y.id || !same_bits(x.xyz, y.xyz) || x.rgb != y.rgb ||
        !same_bits(x.error, y.error) || x.track != y.track)
      return AssertionFailure() << "point3D " << ia->first << " differs";
  }
  return ::testing::AssertionSuccess();
}

// ---- The real colmap executable -----------------------------------------------------------

bool colmap_on_path() {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "");
  for (std::string dir; std::getline(dirs, dir, ':');)
    if (!dir.empty() && ::access((fs::path(dir) / "colmap").c_str(), X_OK) == 0) return true;
  return false;
}

// `colmap model_converter in -> out` (out is created; colmap requires it to exist).
::testing::AssertionResult colmap_convert(const fs::path& in, const fs::path& out,
                                          const char* type) {
  if (!colmap_on_path())
    return ::testing::AssertionFailure()
           << "the `colmap` executable is not on PATH: run scripts/install_deps.sh "
              "(it installs COLMAP 3.8, which this test needs)";
  fs::create_directories(out);
  const fs::path log = out.string() + ".log";
  // Offscreen Qt: harmless for model_converter, and safe if a build ever wants a display.
  const std::string cmd = "QT_QPA_PLATFORM=offscreen colmap model_converter --input_path '" +
                          in.string() + "' --output_path '" + out.string() +
                          "' --output_type " + type + " > '" + log.string() + "' 2>&1";
  const int status = std::system(cmd.c_str());
  if (status != 0)
    return ::testing::AssertionFailure()
           << "`" << cmd << "` exited with status " << status << ":\n" << slurp(log);
  return ::testing::AssertionSuccess();
}

// ---- A hand-made model using every camera model id ----------------------------------------

// COLMAP's camera models (docs "Camera Models" / camera model source): id, name, #params.
struct ExpectedModel {
  int id;
  const char* name;
  int num_params;
};
constexpr ExpectedModel kExpectedModels[] = {
    {0, "SIMPLE_PINHOLE", 3}, {1, "PINHOLE", 4},         {2, "SIMPLE_RADIAL", 4},
    {3, "RADIAL", 5},         {4, "OPENCV", 8},          {5, "OPENCV_FISHEYE", 8},
    {6, "FULL_OPENCV", 12},   {7, "FOV", 5},             {8, "SIMPLE_RADIAL_FISHEYE", 4},
    {9, "RADIAL_FISHEYE", 5}, {10, "THIN_PRISM_FISHEYE", 12},
};

// Doubles that a sloppy text or binary path would alter: thirds, −0, a subnormal, extremes.
constexpr double kAwkward[] = {512.3333333333334, 1.0 / 3.0,  -0.0,  4.9406564584124654e-324,
                               1e-300,           -2.5e-7,     1e300, 0.1,
                               123456789.123456789, -7.0 / 3.0, 2.0 / 3.0, 1e-5};

std::array<double, 4> unit_quat(double w, double x, double y, double z) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  return {w / n, x / n, y / n, z / n};
}

Model make_model() {
  Model m;
  for (const ExpectedModel& e : kExpectedModels) {
    Camera cam;
    cam.id = 100 + static_cast<uint32_t>(e.id);
    cam.model = static_cast<CameraModelId>(e.id);
    cam.width = 640 + static_cast<uint64_t>(e.id);
    cam.height = 480 + 2 * static_cast<uint64_t>(e.id);
    for (int k = 0; k < e.num_params; ++k)
      cam.params.push_back(kAwkward[static_cast<size_t>(k + e.id) % std::size(kAwkward)]);
    m.cameras[cam.id] = cam;
  }
  m.cameras[4000000000u] = Camera{4000000000u, CameraModelId::Pinhole, 1u << 20, 7, {1, 2, 3, 4}};

  const uint64_t big = (uint64_t{1} << 40) + 5;  // point ids are 64-bit
  Image a{1, unit_quat(0.9, 0.1, -0.2, 0.3), {0.5, -1.0 / 3.0, 1e-300}, 100, "a.jpg",
          {{1.5, 2.25, 7}, {3, 4, kNoPoint3D}, {5.125, 6.0 / 7.0, static_cast<int64_t>(big)}}};
  Image b{4000000001u, unit_quat(-0.1, 0.7, 0.0, -0.7), {1e6, 2, -0.0}, 4000000000u, "sub/b.png",
          {{0.0, -0.0, static_cast<int64_t>(big)}, {639.99, 479.99, 7}}};
  Image c{3, {1, 0, 0, 0}, {0, 0, 0}, 110, "c.jpg", {}};  // no observations
  for (Image* img : {&a, &b, &c}) m.images[img->id] = *img;

  m.points[7] = Point3D{7, {1, 2, 3}, {0, 128, 255}, 0.5, {{1, 0}, {4000000001u, 1}}};
  m.points[big] = Point3D{big, {-1e-3, 1.0 / 3.0, 1e5}, {1, 2, 3}, -1, {{4000000001u, 0}, {1, 2}}};
  return m;
}

// File sizes from the documented layout.
uint64_t expected_cameras_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, c] : m.cameras) n += 4 + 4 + 8 + 8 + 8 * c.params.size();
  return n;
}
uint64_t expected_images_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, i] : m.images) n += 4 + 32 + 24 + 4 + i.name.size() + 1 + 8 + 24 * i.points2d.size();
  return n;
}
uint64_t expected_points_bin_size(const Model& m) {
  uint64_t n = 8;
  for (const auto& [id, p] : m.points) n += 8 + 24 + 3 + 8 + 8 + 8 * p.track.size();
  return n;
}

// ---- Camera-model table -------------------------------------------------------------------

TEST(ColmapCameraModels, TableMatchesColmapIdsNamesAndParamCounts) {
  ASSERT_EQ(camera_models().size(), std::size(kExpectedModels));
  for (const ExpectedModel& e : kExpectedModels) {
    const CameraModelInfo& info = camera_model_info(static_cast<CameraModelId>(e.id));
    EXPECT_EQ(static_cast<int>(info.id), e.id);
    EXPECT_STREQ(info.name, e.name);
    EXPECT_EQ(info.num_params, e.num_params) << e.name;
    // The names list has one entry per parameter.
    const std::string_view names = info.param_names;
    EXPECT_EQ(1 + std::count(names.begin(), names.end(), ','), e.num_params)
        << e.name << ": " << names;
    EXPECT_EQ(camera_model_from_name(e.name), static_cast<CameraModelId>(e.id));
  }
  EXPECT_STREQ(camera_model_info(CameraModelId::OpenCV).param_names,
               "fx, fy, cx, cy, k1, k2, p1, p2");
  EXPECT_EQ(camera_model_from_name("opencv"), std::nullopt);  // names are case-sensitive
  EXPECT_EQ(camera_model_from_name("RAD_TAN"), std::nullopt);
  const std::string msg = error_of([] { camera_model_info(static_cast<CameraModelId>(11)); });
  EXPECT_NE(msg.find("unknown camera model id 11"), std::string::npos) << msg;
}

// ---- The real fox capture -----------------------------------------------------------------

TEST(ColmapFox, BinaryHasDocumentedCountsAndValues) {
  const Model m = read_model_binary(kFoxDir);
  ASSERT_EQ(m.cameras.size(), 1u);
  ASSERT_EQ(m.images.size(), 50u);
  ASSERT_EQ(m.points.size(), 12421u);

  const Camera& cam = m.cameras.at(1);
  EXPECT_EQ(cam.model, CameraModelId::OpenCV);
  EXPECT_EQ(cam.width, 540u);
  EXPECT_EQ(cam.height, 960u);
  const std::vector<double> params = {687.79631263596787,     687.33247019469366,
                                      270,                    480,
                                      0.056082542834516767,   -0.077665473853303135,
                                      -0.001721713212307322,  -0.0024992501696264402};
  EXPECT_EQ(cam.params, params);

  const Image& img = m.images.at(50);
  EXPECT_EQ(img.name, "0115.jpg");
  EXPECT_EQ(img.camera_id, 1u);
  EXPECT_EQ(img.qvec_wxyz, (std::array<double, 4>{0.99507498014221873, -0.09450346887353521,
                                                  0.011691374697975812, -0.027535250561839222}));
  EXPECT_EQ(img.tvec, (std::array<double, 3>{-3.14614344392279, -1.8568607848667402,
                                             0.45304123320618322}));
  ASSERT_FALSE(img.points2d.empty());
  EXPECT_EQ(img.points2d[0], (Observation{406.67733764648438, 1.4702727794647217, -1}));

  const Point3D& pt = m.points.at(11548);
  EXPECT_EQ(pt.xyz, (std::array<double, 3>{2.7414492142275853, 4.0460018764980825,
                                           3.7612355408920193}));
  EXPECT_EQ(pt.rgb, (std::array<uint8_t, 3>{193, 201, 203}));
  EXPECT_EQ(pt.error, 0.63748205236417477);
  EXPECT_EQ(pt.track, (std::vector<TrackElement>{{25, 3718}, {27, 3200}, {29, 3141}, {30, 1113}}));

  size_t observations = 0, track_total = 0;
  for (const auto& [id, i] : m.images)
    for (const Observation& o : i.points2d) observations += o.point3d_id >= 0;
  for (const auto& [id, p] : m.points) track_total += p.track.size();
  EXPECT_EQ(observations, 83121u);
  EXPECT_EQ(track_total, 83121u);

  // Every byte of the files is accounted for by the documented layout.
  EXPECT_EQ(fs::file_size(kFoxDir / "cameras.bin"), expected_cameras_bin_size(m));
  EXPECT_EQ(fs::file_size(kFoxDir / "images.bin"), expected_images_bin_size(m));
  EXPECT_EQ(fs::file_size(kFoxDir / "points3D.bin"), expected_points_bin_size(m));

  EXPECT_TRUE(identical(read_model(kFoxDir), m));  // dispatch picks the binary files
}

// COLMAP writes text with 17 significant digits, which identifies a double uniquely, so the
// text model must equal the binary one bit for bit: tolerance 0.
TEST(ColmapFox, ColmapTextConversionEqualsBinaryExactly) {
  TempDir tmp;
  const fs::path txt = tmp / "txt";
  ASSERT_TRUE(colmap_convert(kFoxDir, txt, "TXT"));
  ASSERT_TRUE(fs::exists(txt / "images.txt"));
  const Model bin = read_model_binary(kFoxDir);
  EXPECT_TRUE(identical(read_model_text(txt), bin));
  EXPECT_TRUE(identical(read_model(txt), bin));  // dispatch falls back to text
}

TEST(ColmapFox, ColmapReadsOurBinaryAndOurTextBack) {
  TempDir tmp;
  const Model fox = read_model_binary(kFoxDir);

  write_model_binary(fox, tmp / "ours_bin");
  // Same records in id order instead of COLMAP's hash order: same sizes.
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    EXPECT_EQ(fs::file_size(tmp / "ours_bin" / f), fs::file_size(kFoxDir / f)) << f;
  ASSERT_TRUE(colmap_convert(tmp / "ours_bin", tmp / "colmap_txt", "TXT"));
  EXPECT_TRUE(identical(read_model_text(tmp / "colmap_txt"), fox));

  write_model_text(fox, tmp / "ours_txt");
  ASSERT_TRUE(colmap_convert(tmp / "ours_txt", tmp / "colmap_bin", "BIN"));
  EXPECT_TRUE(identical(read_model_binary(tmp / "colmap_bin"), fox));
  EXPECT_TRUE(identical(read_model_text(tmp / "ours_txt"), fox));
}

TEST(ColmapFox, ColmapAcceptsEveryCameraModelWeWrite) {
  TempDir tmp;
  const Model m = make_model();
  write_model_binary(m, tmp / "ours_bin");
  ASSERT_TRUE(colmap_convert(tmp / "ours_bin", tmp / "colmap_txt", "TXT"));
  EXPECT_TRUE(identical(read_model_text(tmp / "colmap_txt"), m));

  write_model_text(m, tmp / "ours_txt");
  ASSERT_TRUE(colmap_convert(tmp / "ours_txt", tmp / "colmap_bin", "BIN"));
  EXPECT_TRUE(identical(read_model_binary(tmp / "colmap_bin"), m));
}

// ---- Round trips of a hand-made model -----------------------------------------------------

TEST(ColmapRoundTrip, BinaryIsBitExact) {
  TempDir tmp;
  Model m = make_model();
  m.images.at(3).qvec_wxyz = {2, 0, 0, 0};  // not unit: kept exactly as given
  write_model_binary(m, tmp.path());
  EXPECT_EQ(fs::file_size(tmp / "cameras.bin"), expected_cameras_bin_size(m));
  EXPECT_EQ(fs::file_size(tmp / "images.bin"), expected_images_bin_size(m));
  EXPECT_EQ(fs::file_size(tmp / "points3D.bin"), expected_points_bin_size(m));
  // Spot-check the layout at documented offsets: count, first camera's id and model id.
  const std::string cams = slurp(tmp / "cameras.bin");
  EXPECT_EQ(peek<uint64_t>(cams, 0), m.cameras.size());
  EXPECT_EQ(peek<uint32_t>(cams, 8), 100u);
  EXPECT_EQ(peek<int32_t>(cams, 12), 0);  // SIMPLE_PINHOLE
  const std::string imgs = slurp(tmp / "images.bin");
  const size_t b_obs = image_records(imgs).at(2) + 64 + std::strlen("sub/b.png") + 1 + 8;
  EXPECT_EQ(peek<uint64_t>(imgs, image_records(imgs).at(0) + 64 + 6 + 8 + 24 + 16),
            std::numeric_limits<uint64_t>::max());  // a.jpg points2D[1]: "no point" marker
  EXPECT_EQ(peek<uint64_t>(imgs, b_obs + 16), (uint64_t{1} << 40) + 5);

  const Model back = read_model_binary(tmp.path());
  EXPECT_TRUE(identical(back, m));
  EXPECT_EQ(back, m);
  TempDir again_dir;
  write_model_binary(back, again_dir / "again");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    EXPECT_TRUE(slurp(again_dir / "again" / f) == slurp(tmp / f)) << f << " bytes differ";
}

TEST(ColmapRoundTrip, TextIsExact) {
  TempDir tmp;
  Model m = make_model();
  m.images.at(3).qvec_wxyz = {2, 0, 0, 0};
  m.images.at(3).name = "dir with spaces/c 1.jpg";  // our reader keeps the rest of the line
  write_model_text(m, tmp.path());
  const Model back = read_model_text(tmp.path());
  EXPECT_TRUE(identical(back, m));
  EXPECT_EQ(back.images.at(3).name, "dir with spaces/c 1.jpg");
  // The image without observations is written with an empty second line.
  EXPECT_NE(slurp(tmp / "images.txt").find(" 110 dir with spaces/c 1.jpg\n\n"), std::string::npos);
}

TEST(ColmapRoundTrip, EmptyPoints3DIsValid) {
  TempDir tmp;
  Model m = make_model();
  m.points.clear();
  for (auto& [id, img] : m.images)
    for (Observation& o : img.points2d) o.point3d_id = kNoPoint3D;

  write_model_binary(m, tmp / "bin");
  EXPECT_EQ(slurp(tmp / "bin" / "points3D.bin"), std::string(8, '\0'));  // just a zero count
  EXPECT_TRUE(identical(read_model_binary(tmp / "bin"), m));

  write_model_text(m, tmp / "txt");
  spit(tmp / "txt" / "points3D.txt", "# no points\n");
  EXPECT_TRUE(identical(read_model_text(tmp / "txt"), m));
  spit(tmp / "txt" / "points3D.txt", "");
  EXPECT_TRUE(identical(read_model_text(tmp / "txt"), m));
}

TEST(ColmapRoundTrip, WritersRefuseModelsTheReadersWouldReject) {
  TempDir tmp;
  Model m = make_model();
  m.images.at(3).camera_id = 999;
  expect_error([&] { write_model_binary(m, tmp / "bin"); }, tmp / "bin" / "images.bin",
               {"image 3: camera_id 999 is not in"});
  EXPECT_FALSE(fs::exists(tmp / "bin"));  // nothing written

  m = make_model();
  m.images.at(3).name = "two\nlines.jpg";
  expect_error([&] { write_model_text(m, tmp / "txt"); }, tmp / "txt" / "images.txt",
               {"line break"});
  EXPECT_FALSE(fs::exists(tmp / "txt"));

  m = make_model();
  m.points.begin()->second.track.pop_back();  // observation no longer listed in the track
  expect_error([&] { write_model_binary(m, tmp / "bin"); }, tmp / "bin" / "images.bin",
               {"track does not list this observation"});
}

// Every single-byte corruption of a small model either reads as a valid model or throws
// ColmapError: never another exception, a crash or a hang. Two edits per byte: all bits
// flipped (huge counts, lost NUL terminators, unknown model ids) and the lowest bit flipped
// (counts and ids off by one). The model keeps only the cameras its images use, to stay fast.
TEST(ColmapRoundTrip, SingleByteCorruptionsNeverEscapeAsOtherErrors) {
  TempDir tmp;
  Model m = make_model();
  std::erase_if(m.cameras, [&](const auto& kv) {
    for (const auto& [id, img] : m.images)
      if (img.camera_id == kv.first) return false;
    return true;
  });
  write_model_binary(m, tmp.path());
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const std::string good = slurp(tmp / f);
    for (size_t off = 0; off < good.size(); ++off) {
      for (const char bad_byte : {static_cast<char>(~good[off]), static_cast<char>(good[off] ^ 1)}) {
        std::string bad = good;
        bad[off] = bad_byte;
        spit(tmp / f, bad);
        try {
          read_model_binary(tmp.path());
        } catch (const ColmapError&) {
        }  // anything else escapes and fails the test
      }
    }
    spit(tmp / f, good);
  }
}

// ---- Bad binary input (corrupted copies of fox) -------------------------------------------

class ColmapBadBinary : public ::testing::Test {
 protected:
  TempDir tmp_;
  fs::path dir_ = copy_fox(tmp_ / "model");
  fs::path cameras_ = dir_ / "cameras.bin";
  fs::path images_ = dir_ / "images.bin";
  fs::path points_ = dir_ / "points3D.bin";

  void read_expecting(const fs::path& file, std::initializer_list<std::string_view> fragments) {
    expect_error([&] { read_model_binary(dir_); }, file, fragments);
  }
  // Applies `edit` to a copy of `file`'s bytes and writes them back.
  void edit(const fs::path& file, const std::function<void(std::string&)>& f) {
    std::string bytes = slurp(file);
    f(bytes);
    spit(file, bytes);
  }
};

TEST_F(ColmapBadBinary, MissingFile) {
  fs::remove(points_);
  read_expecting(points_, {"file not found"});
}

TEST_F(ColmapBadBinary, ReadModelWithNeitherFormatNamesBothCandidates) {
  const fs::path empty = tmp_ / "empty";
  fs::create_directories(empty);
  const std::string msg = error_of([&] { read_model(empty); });
  EXPECT_NE(msg.find((empty / "cameras.bin").string()), std::string::npos) << msg;
  EXPECT_NE(msg.find((empty / "cameras.txt").string()), std::string::npos) << msg;
  expect_error([&] { read_model(tmp_ / "nope"); }, tmp_ / "nope", {"directory not found"});
}

TEST_F(ColmapBadBinary, TruncatedCamerasAtEveryLength) {
  const std::string good = slurp(cameras_);
  for (size_t len = 0; len < good.size(); ++len) {
    spit(cameras_, good.substr(0, len));
    const std::string msg = error_of([&] { read_model_binary(dir_); });
    EXPECT_NE(msg.find(cameras_.string()), std::string::npos) << len << ": " << msg;
    EXPECT_TRUE(msg.find("truncated") != std::string::npos ||
                msg.find("count of cameras") != std::string::npos)
        << len << ": " << msg;
  }
  spit(cameras_, good.substr(0, 90));  // inside the 8th param (bytes 88..96)
  read_expecting(cameras_, {"byte 88", "truncated", "params", "only 2 left"});
}

TEST_F(ColmapBadBinary, TruncatedLastRecords) {
  edit(images_, [](std::string& b) { b.resize(b.size() - 3); });
  // The last image's num_points2D no longer fits: caught at the count, before reading on.
  read_expecting(images_, {"image record 50 of 50", "count of points2D", "truncated file"});
  copy_fox(dir_);
  edit(points_, [](std::string& b) { b.resize(b.size() - 1); });
  read_expecting(points_, {"point3D record 12421 of 12421", "count of track elements",
                           "truncated file"});
}

TEST_F(ColmapBadBinary, HugeCountsAreRejectedBeforeAllocating) {
  const uint64_t huge = uint64_t{1} << 60;
  edit(points_, [&](std::string& b) { patch(b, 0, huge); });
  read_expecting(points_, {"count of points3D is 1152921504606846976", "at least 51 bytes"});

  copy_fox(dir_);
  edit(images_, [&](std::string& b) {  // num_points2D of the first image
    patch(b, b.find('\0', 8 + 64) + 1, huge);
  });
  read_expecting(images_, {"count of points2D is 1152921504606846976"});

  copy_fox(dir_);
  edit(points_, [&](std::string& b) { patch(b, 8 + 43, huge); });  // first track length
  read_expecting(points_, {"count of track elements is 1152921504606846976"});

  copy_fox(dir_);
  edit(cameras_, [&](std::string& b) { patch(b, 0, uint64_t{2}); });  // 2 cameras, bytes for 1
  read_expecting(cameras_, {"truncated"});
}

TEST_F(ColmapBadBinary, UnknownCameraModelId) {
  edit(cameras_, [](std::string& b) { patch(b, 12, int32_t{42}); });
  read_expecting(cameras_, {"byte 8", "camera 1: unknown camera model id 42"});
  edit(cameras_, [](std::string& b) { patch(b, 12, int32_t{-1}); });
  read_expecting(cameras_, {"unknown camera model id -1"});
}

TEST_F(ColmapBadBinary, NonPositiveWidthOrHeight) {
  edit(cameras_, [](std::string& b) { patch(b, 16, uint64_t{0}); });
  read_expecting(cameras_, {"camera 1: width must be positive, got 0"});
  copy_fox(dir_);
  edit(cameras_, [](std::string& b) { patch(b, 24, uint64_t{0}); });
  read_expecting(cameras_, {"camera 1: height must be positive, got 0"});
}

TEST_F(ColmapBadBinary, NonFiniteCameraParams) {
  edit(cameras_, [](std::string& b) { patch(b, 32, std::nan("")); });
  read_expecting(cameras_, {"camera 1: param 0 (fx) is nan"});
  copy_fox(dir_);
  edit(cameras_, [](std::string& b) { patch(b, 32 + 8 * 5, -HUGE_VAL); });
  read_expecting(cameras_, {"camera 1: param 5 (k2) is -inf"});
}

TEST_F(ColmapBadBinary, NonFiniteImagePose) {
  const uint32_t first_id = peek<uint32_t>(slurp(images_), 8);
  const std::string who = "image " + std::to_string(first_id) + ": ";
  edit(images_, [](std::string& b) { patch(b, 8 + 4 + 8, HUGE_VAL); });  // qx
  read_expecting(images_, {who + "qx is inf"});
  copy_fox(dir_);
  edit(images_, [](std::string& b) { patch(b, 8 + 36 + 8, std::nan("")); });  // ty
  read_expecting(images_, {who + "ty is nan"});
}

TEST_F(ColmapBadBinary, ZeroNormQuaternion) {
  edit(images_, [](std::string& b) {
    for (size_t k = 0; k < 4; ++k) patch(b, 12 + 8 * k, 0.0);
  });
  read_expecting(images_, {"quaternion has zero norm (0, 0, 0, 0)"});
}

TEST_F(ColmapBadBinary, NonFinitePointPosition) {
  const uint64_t first_id = peek<uint64_t>(slurp(points_), 8);
  edit(points_, [](std::string& b) { patch(b, 8 + 8 + 16, std::nan("")); });  // z
  read_expecting(points_, {"point3D " + std::to_string(first_id) + ": z is nan"});
}

TEST_F(ColmapBadBinary, DuplicateImageName) {
  edit(images_, [](std::string& b) {
    const auto recs = image_records(b);
    const std::string first(b.data() + recs[0] + 64);
    ASSERT_EQ(first.size(), std::strlen(b.data() + recs[1] + 64));  // fox names: "NNNN.jpg"
    std::memcpy(b.data() + recs[1] + 64, first.data(), first.size());
  });
  read_expecting(images_, {"duplicate image name '", ".jpg'"});
}

TEST_F(ColmapBadBinary, DuplicateIds) {
  edit(images_, [](std::string& b) {
    const auto recs = image_records(b);
    patch(b, recs[1], peek<uint32_t>(b, recs[0]));
  });
  read_expecting(images_, {"image record 2 of 50", "duplicate image id"});

  copy_fox(dir_);
  edit(points_, [](std::string& b) {
    const auto recs = point_records(b);
    patch(b, recs[1], peek<uint64_t>(b, recs[0]));
  });
  read_expecting(points_, {"point3D record 2 of 12421", "duplicate point3D id"});

  copy_fox(dir_);
  edit(cameras_, [](std::string& b) {  // the same camera record twice
    b += b.substr(8);
    patch(b, 0, uint64_t{2});
  });
  read_expecting(cameras_, {"byte 96", "duplicate camera id 1"});
}

TEST_F(ColmapBadBinary, ImageWithUnknownCamera) {
  const uint32_t first_id = peek<uint32_t>(slurp(images_), 8);
  edit(images_, [](std::string& b) { patch(b, 8 + 60, uint32_t{7}); });
  read_expecting(images_, {"image " + std::to_string(first_id) + ": camera_id 7 is not in " +
                           cameras_.string()});
}

TEST_F(ColmapBadBinary, TrailingGarbage) {
  edit(cameras_, [](std::string& b) { b += "xyz"; });
  read_expecting(cameras_, {"byte 96", "3 trailing bytes"});
  copy_fox(dir_);
  edit(points_, [](std::string& b) { b += std::string(8, '\0'); });
  read_expecting(points_, {"8 trailing bytes"});
}

TEST_F(ColmapBadBinary, UnterminatedImageName) {
  edit(images_, [](std::string& b) {  // one image whose name runs to the end of the file
    b.resize(8 + 64);
    patch(b, 0, uint64_t{1});
    b += "no_nul_here!";
  });
  read_expecting(images_, {"byte 72", "image name has no terminating NUL", "12 bytes left"});
  // A long run of non-NUL bytes ends at the end of the file, not beyond it.
  edit(images_, [](std::string& b) { b += std::string(1 << 20, 'a'); });
  read_expecting(images_, {"image name has no terminating NUL"});
}

TEST_F(ColmapBadBinary, ObservationPointIdOutOfRange) {
  edit(images_, [](std::string& b) {
    patch(b, b.find('\0', 8 + 64) + 1 + 8 + 16, uint64_t{1} << 63);  // points2D[0] id
  });
  read_expecting(images_, {"points2D[0] has point3D_id 9223372036854775808"});
}

TEST_F(ColmapBadBinary, TracksAndObservationsMustAgree) {
  const std::string pts = slurp(points_);
  const uint64_t pid = peek<uint64_t>(pts, 8);
  const std::string who = "point3D " + std::to_string(pid) + " track[0]: ";
  edit(points_, [](std::string& b) { patch(b, 8 + 51, uint32_t{9999}); });
  read_expecting(points_, {who + "image 9999 is not in " + images_.string()});

  edit(points_, [&](std::string& b) {
    b = pts;
    patch(b, 8 + 51 + 4, uint32_t{4000000});
  });
  read_expecting(points_, {who + "point2D_idx 4000000 is out of range"});

  // Point the first image's first untriangulated keypoint at a point that does not list it.
  spit(points_, pts);
  edit(images_, [&](std::string& b) {
    size_t obs = b.find('\0', 8 + 64) + 1 + 8;
    while (peek<uint64_t>(b, obs + 16) != std::numeric_limits<uint64_t>::max()) obs += 24;
    patch(b, obs + 16, pid);
  });
  read_expecting(images_, {"track does not list this observation"});
}

// ---- Bad text input -----------------------------------------------------------------------

constexpr const char* kCamerasTxt =
    "# Camera list with one line of data per camera:\n"
    "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
    "\n"
    "1 PINHOLE 640 480 500 501 320 240\n"
    "2 SIMPLE_RADIAL 640 480 500 320 240 0.01\n";
constexpr const char* kImagesTxt =
    "# Image list with two lines of data per image:\n"
    "1 1 0 0 0 0 0 0 1 a.jpg\n"
    "10 20 7 30 40 -1\n"
    "2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n"
    "11 21 7\n";
constexpr const char* kPointsTxt =
    "# 3D point list\n"
    "7 1 2 3 255 0 10 0.25 1 0 2 0\n";

class ColmapBadText : public ::testing::Test {
 protected:
  TempDir tmp_;
  fs::path cameras_ = tmp_ / "cameras.txt";
  fs::path images_ = tmp_ / "images.txt";
  fs::path points_ = tmp_ / "points3D.txt";

  void SetUp() override {
    spit(cameras_, kCamerasTxt);
    spit(images_, kImagesTxt);
    spit(points_, kPointsTxt);
  }
  void read_expecting(const fs::path& file, std::initializer_list<std::string_view> fragments) {
    expect_error([&] { read_model_text(tmp_.path()); }, file, fragments);
  }
};

TEST_F(ColmapBadText, BaseFilesAreValid) {
  const Model m = read_model_text(tmp_.path());
  EXPECT_EQ(m.cameras.at(2).params, (std::vector<double>{500, 320, 240, 0.01}));
  EXPECT_EQ(m.images.at(1).points2d,
            (std::vector<Observation>{{10, 20, 7}, {30, 40, kNoPoint3D}}));
  EXPECT_EQ(m.points.at(7).track, (std::vector<TrackElement>{{1, 0}, {2, 0}}));
  EXPECT_EQ(m.points.at(7).rgb, (std::array<uint8_t, 3>{255, 0, 10}));
}

TEST_F(ColmapBadText, MissingFile) {
  fs::remove(images_);
  read_expecting(images_, {"file not found"});
}

TEST_F(ColmapBadText, UnknownModelName) {
  spit(cameras_, "# c\n1 PINHOLLE 640 480 500 501 320 240\n");
  read_expecting(cameras_, {":2: camera 1: unknown camera model 'PINHOLLE'"});
}

TEST_F(ColmapBadText, WrongNumberOfParams) {
  spit(cameras_, "# c\n\n\n1 OPENCV 640 480 500 501 320 240\n");
  read_expecting(cameras_, {":4: camera 1: OPENCV needs 8 params (fx, fy, cx, cy, k1, k2, p1, p2), got 4"});
}

TEST_F(ColmapBadText, NonPositiveSize) {
  spit(cameras_, "1 PINHOLE 640 -480 500 501 320 240\n");
  read_expecting(cameras_, {":1: camera 1: HEIGHT must be positive, got -480"});
  spit(cameras_, "1 PINHOLE 0 480 500 501 320 240\n");
  read_expecting(cameras_, {":1: camera 1: WIDTH must be positive, got 0"});
}

TEST_F(ColmapBadText, NonFiniteValues) {
  spit(cameras_, "1 PINHOLE 640 480 500 inf 320 240\n2 SIMPLE_RADIAL 640 480 500 320 240 0\n");
  read_expecting(cameras_, {":1: camera 1: param 1 (fy) is inf"});
  SetUp();
  spit(images_, "1 nan 0 0 0 0 0 0 1 a.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n11 21 7\n");
  read_expecting(images_, {":1: image 1: qw is nan"});
  SetUp();
  spit(points_, "7 1 -inf 3 255 0 10 0.25 1 0 2 0\n");
  read_expecting(points_, {":1: point3D 7: y is -inf"});
}

TEST_F(ColmapBadText, ZeroNormQuaternion) {
  spit(images_, "1 0 0 0 0 0 0 0 1 a.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n11 21 7\n");
  read_expecting(images_, {":1: image 1: quaternion has zero norm"});
}

TEST_F(ColmapBadText, MalformedLinesReportTheLineNumber) {
  spit(cameras_, "# c\n1 PINHOLE 640 480 500 5o1 320 240\n");
  read_expecting(cameras_, {":2: PARAMS[1] '5o1' is not a number"});
  SetUp();
  spit(cameras_, "1 PINHOLE 640\n");
  read_expecting(cameras_, {":1: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got 3 fields"});
  SetUp();
  spit(images_, "# i\n# i\n1 1 0 0 0 0 0 0 1 a.jpg\n10 20 7 30 40\n");
  read_expecting(images_, {":4: POINTS2D line has 5 fields, not a multiple of 3"});
  SetUp();
  spit(images_, "1 1 0 0 0 0 0 1 a.jpg\n\n");
  read_expecting(images_, {":1: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got 9"});
  SetUp();
  spit(images_, "1 1 0 0 0 0 0 0 x1 a.jpg\n\n");
  read_expecting(images_, {":1: CAMERA_ID 'x1' is not an unsigned 32-bit integer"});
  SetUp();
  spit(images_, "1 1 0 0 0 0 0 0 1 a.jpg\n10 20 -2\n");
  read_expecting(images_, {":1: image 1: points2D[0] has point3D_id -2"});
  SetUp();
  spit(points_, "# p\n7 1 2 3 256 0 10 0.25 1 0 2 0\n");
  read_expecting(points_, {":2: R must be 0..255, got 256"});
  SetUp();
  spit(points_, "7 1 2 3 255 0 10 0.25 1 0 2\n");
  read_expecting(points_, {":1: expected POINT3D_ID X Y Z R G B ERROR", "got 11 fields"});
  SetUp();
  spit(points_, "7 1 2 3 255 0 10 0.25 1 0 2 99999999999\n");
  read_expecting(points_, {":1: POINT2D_IDX[1] '99999999999' is not an unsigned 32-bit integer"});
}

TEST_F(ColmapBadText, MissingPointsLineAtEndOfFile) {
  spit(images_, "1 1 0 0 0 0 0 0 1 a.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n");
  read_expecting(images_, {":3: image 2: file ends before its POINTS2D line"});
}

TEST_F(ColmapBadText, DuplicatesAndDanglingReferences) {
  spit(cameras_, std::string(kCamerasTxt) + "1 PINHOLE 10 10 1 1 5 5\n");
  read_expecting(cameras_, {":6: duplicate camera id 1"});
  SetUp();
  spit(images_, "1 1 0 0 0 0 0 0 1 a.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 a.jpg\n11 21 7\n");
  read_expecting(images_, {"duplicate image name 'a.jpg' (images 1 and 2)"});
  SetUp();
  spit(images_, std::string(kImagesTxt) + "1 1 0 0 0 0 0 0 1 c.jpg\n\n");
  read_expecting(images_, {":6: duplicate image id 1"});
  SetUp();
  spit(images_, "1 1 0 0 0 0 0 0 3 a.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n11 21 7\n");
  read_expecting(images_, {"image 1: camera_id 3 is not in " + cameras_.string()});
  SetUp();
  spit(points_, std::string(kPointsTxt) + "7 0 0 0 1 1 1 0\n");
  read_expecting(points_, {":3: duplicate point3D id 7"});
  SetUp();
  spit(points_, "8 1 2 3 255 0 10 0.25 1 0 2 0\n");
  read_expecting(points_, {"point3D 8 track[0]: image 1 points2D[0] has point3D_id 7, not 8"});
}

}  // namespace
