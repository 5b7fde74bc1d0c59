// COLMAP sparse-model I/O against the real fox capture, the real `colmap` executable
// (model_converter in both directions) and exact round trips of every camera model.
//
// Expected values come from outside our code: the fox numbers are copied from the
// cameras/images/points3D.txt that `colmap model_converter` writes for the fox capture's
// sparse/0 (17 significant digits, so the literals below are the exact doubles), and file
// sizes come from the documented byte layout.
#include <gtest/gtest.h>

#include "support/colmap_fixtures.hpp"

using namespace colmap_test;

namespace {

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
    EXPECT_EQ(1 + std::count(names.begin(), names.end(), ','), e.num_params) << e.name << ": " << names;
    EXPECT_EQ(camera_model_from_name(e.name), static_cast<CameraModelId>(e.id));
  }
  EXPECT_STREQ(camera_model_info(CameraModelId::OpenCV).param_names, "fx, fy, cx, cy, k1, k2, p1, p2");
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
  const std::vector<double> params = {
      687.79631263596787,    687.33247019469366,    270, 480, 0.056082542834516767, -0.077665473853303135,
      -0.001721713212307322, -0.0024992501696264402};
  EXPECT_EQ(cam.params, params);

  const Image& img = m.images.at(50);
  EXPECT_EQ(img.name, "0115.jpg");
  EXPECT_EQ(img.camera_id, 1u);
  EXPECT_EQ(img.qvec_wxyz, (std::array<double, 4>{0.99507498014221873, -0.09450346887353521, 0.011691374697975812,
                                                  -0.027535250561839222}));
  EXPECT_EQ(img.tvec, (std::array<double, 3>{-3.14614344392279, -1.8568607848667402, 0.45304123320618322}));
  ASSERT_FALSE(img.points2d.empty());
  EXPECT_EQ(img.points2d[0], (Observation{406.67733764648438, 1.4702727794647217, -1}));

  const Point3D& pt = m.points.at(11548);
  EXPECT_EQ(pt.xyz, (std::array<double, 3>{2.7414492142275853, 4.0460018764980825, 3.7612355408920193}));
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
  expect_error([&] { write_model_text(m, tmp / "txt"); }, tmp / "txt" / "images.txt", {"line break"});
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

}  // namespace
