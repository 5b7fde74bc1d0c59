// COLMAP sparse models: one test per kind of bad input, binary and text. Corrupt files are
// made by patching bytes of the fox model at documented offsets, or by editing text lines;
// every error must name the file and what is wrong.
#include <gtest/gtest.h>

#include "support/colmap_fixtures.hpp"

using namespace colmap_test;

namespace {

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
    EXPECT_TRUE(msg.find("truncated") != std::string::npos || msg.find("count of cameras") != std::string::npos)
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
  read_expecting(points_, {"point3D record 12421 of 12421", "count of track elements", "truncated file"});
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
  read_expecting(images_, {"image " + std::to_string(first_id) + ": camera_id 7 is not in " + cameras_.string()});
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
  EXPECT_EQ(m.images.at(1).points2d, (std::vector<Observation>{{10, 20, 7}, {30, 40, kNoPoint3D}}));
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

TEST_F(ColmapBadText, ImageNamesThatLeaveTheImageFolder) {
  // Training writes renders/<name>.png under --out and reads images/<name>: an absolute name
  // or a '..' would reach outside both folders.
  spit(images_, "1 1 0 0 0 0 0 0 1 /tmp/x.jpg\n\n");
  read_expecting(images_, {":1: image 1: image name '/tmp/x.jpg' is an absolute path"});
  spit(images_, "1 1 0 0 0 0 0 0 1 ../../x.jpg\n\n");
  read_expecting(images_, {"image name '../../x.jpg' leaves the image folder"});
  spit(images_, "1 1 0 0 0 0 0 0 1 a/../../x.jpg\n\n");
  read_expecting(images_, {"leaves the image folder"});
  // A subfolder is a relative name that stays inside: accepted.
  spit(images_, "1 1 0 0 0 0 0 0 1 cam1/a..b.jpg\n10 20 7 30 40 -1\n2 0.5 0.5 0.5 0.5 1 2 3 2 b.jpg\n11 21 7\n");
  EXPECT_EQ(read_model_text(tmp_.path()).images.at(1).name, "cam1/a..b.jpg");
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
