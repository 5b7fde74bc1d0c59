// Bad input a hostile or careless user brings, refused with one clear error before anything is
// trained or written: JSON nested past the stack, an output folder on top of the input or the
// root, an all-black mask, one photo under two names, cameras with no baseline or in other
// units than the points, impossible lenses, names that are not UTF-8, distractor counts no
// machine holds, and a bench grid of the wrong shape.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>

#include "desplat/io/json_text.hpp"
#include "desplat/io/output_folder.hpp"
#include "desplat/jobs/bench_run.hpp"
#include "desplat/jobs/model_folder.hpp"
#include "desplat/synth/synth.hpp"
#include "desplat/train/distractors.hpp"
#include "support/scene_fixtures.hpp"
#include "support/synthetic_views.hpp"

namespace scene_test {
namespace {

using desplat::testing::error_of;
using desplat::testing::TempDir;

// What any exception `fn` throws says ("no exception" when it returns).
template <class Fn>
std::string message_of(Fn&& fn) {
  try {
    fn();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "no exception";
}

std::string nested(int levels) { return std::string(size_t(levels), '[') + std::string(size_t(levels), ']'); }
std::string nested_object(int levels) {
  std::string s;
  for (int i = 0; i < levels; ++i) s += "{\"a\":";
  s += "1";
  return s + std::string(size_t(levels), '}');
}

// ---- JSON nesting -------------------------------------------------------------------------

TEST(HostileJson, NestingIsBoundedAtTheStatedDepth) {
  EXPECT_NO_THROW(parse_json_bounded(nested(kMaxJsonDepth), "x"));
  EXPECT_CONTAINS(error_of<JsonTextError>([] { parse_json_bounded(nested(kMaxJsonDepth + 1), "the text"); }),
                  "the text: JSON nested deeper than 256 levels");
  // Far past where walking it would overflow the stack.
  EXPECT_CONTAINS(error_of<JsonTextError>([] { parse_json_bounded(nested_object(200000), "deep.json"); }),
                  "deep.json: JSON nested deeper");
  // Malformed text: the source and the place, without the library's exception prefix.
  const std::string bad = error_of<JsonTextError>([] { parse_json_bounded("{\"a\": ", "grid.json"); });
  EXPECT_CONTAINS(bad, "grid.json is not valid JSON: parse error at line 1, column 7: syntax error");
  EXPECT_EQ(bad.find("json.exception"), std::string::npos) << bad;
}

TEST(HostileJson, EveryReaderRefusesDeepNesting) {
  TempDir dir("hostile_json");
  const fs::path deep = dir.path() / "deep.json";
  desplat::testing::spit(deep, nested_object(100000));
  EXPECT_CONTAINS(message_of([&] { synth::load_description(deep); }), "JSON nested deeper than 256 levels");
  EXPECT_CONTAINS(message_of([&] { read_bench_grid(deep); }), "JSON nested deeper than 256 levels");
  fs::create_directories(dir.path() / "model");
  desplat::testing::spit(dir.path() / "model" / "config.json", nested_object(100000));
  EXPECT_CONTAINS(message_of([&] { ModelFolder(dir.path() / "model").read_config(); }),
                  "JSON nested deeper than 256 levels");
}

// ---- Output folders -----------------------------------------------------------------------

TEST(HostileOutput, OutputOnTheInputOrTheRootIsRefused) {
  TempDir dir("hostile_out");
  const fs::path data = dir.path() / "scene";
  fs::create_directories(data / "images");
  fs::create_directories(data / "sparse" / "0");
  auto err = [&](const fs::path& out) {
    return message_of([&] { check_output_folder("--out", out, {{"--data", data}}); });
  };
  EXPECT_CONTAINS(err(data), "are the same folder");
  EXPECT_CONTAINS(err(data / "images"), "lies inside --data");
  EXPECT_CONTAINS(err(data / "sparse" / "0" / "new"), "lies inside --data");
  EXPECT_CONTAINS(err(data / "images" / ".." / ".."), "contains --data");  // the scene's parent
  EXPECT_CONTAINS(err(dir.path() / "scene" / "."), "are the same folder");
  EXPECT_CONTAINS(err("/"), "is the filesystem root");
  EXPECT_CONTAINS(err("/../.."), "is the filesystem root");
  EXPECT_CONTAINS(err(""), "--out is empty");
  desplat::testing::spit(dir.path() / "a_file", "x");
  EXPECT_CONTAINS(err(dir.path() / "a_file"), "is a file, not a folder");
  fs::create_symlink(data, dir.path() / "link");
  EXPECT_CONTAINS(err(dir.path() / "link"), "are the same folder");
  EXPECT_EQ(err(dir.path() / "elsewhere"), "no exception");
  EXPECT_EQ(err(dir.path() / "scene_out"), "no exception");  // a sibling with a common prefix
  // desplat_render may write inside the model folder, not over it.
  const fs::path model = dir.path() / "model";
  fs::create_directories(model);
  EXPECT_EQ(message_of([&] {
              check_output_folder("--out", model / "renders", {{"--model", model, true}});
            }),
            "no exception");
  EXPECT_CONTAINS(message_of([&] { check_output_folder("--out", model, {{"--model", model, true}}); }), "same folder");
}

// ---- Scenes -------------------------------------------------------------------------------

struct SceneCase {
  TempDir dir{"hostile_scene"};
  Warnings warnings;
  fs::path data() const { return dir.path() / "scene"; }
  std::string load_error() {
    SceneOptions o = quiet_options(dir.path() / "cache", warnings);
    return message_of([&] { load_colmap_scene(data(), o); });
  }
};

// The model as text, with images.txt passed through `edit`: for models the writers refuse.
void write_text_model(const fs::path& sparse, const colmap::Model& m, const std::function<void(std::string&)>& edit) {
  fs::remove(sparse / "cameras.bin"), fs::remove(sparse / "images.bin"), fs::remove(sparse / "points3D.bin");
  colmap::write_model_text(m, sparse);
  std::string images = desplat::testing::slurp(sparse / "images.txt");
  edit(images);
  desplat::testing::spit(sparse / "images.txt", images);
}

TEST(HostileScene, TwoNamesOfOneFileAreRefused) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data());
  write_text_model(c.data() / "sparse/0", s.model, [](std::string& images) {
    images += "9 1 0 0 0 0 0 4 1 ./img_0.png\n\n";  // a fifth pose for img_0.png
  });
  const std::string e = c.load_error();
  EXPECT_CONTAINS(e, "name the same file img_0.png");
  EXPECT_CONTAINS(e, "'./img_0.png'");  // both spellings are named
}

TEST(HostileScene, NamesThatAreNotUtf8AreRefused) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data());
  write_text_model(c.data() / "sparse/0", s.model,
                   [](std::string& images) { images.replace(images.find("img_1.png"), 9, "caf\xe9.png"); });
  const std::string e = c.load_error();
  EXPECT_CONTAINS(e, "'caf\\xe9.png' is not UTF-8 text");
  EXPECT_EQ(e.find("json.exception"), std::string::npos) << e;
}

TEST(HostileScene, ZeroOrNegativeFocalLengthNamesTheCameraAndFile) {
  for (const double f : {0.0, -40.0}) {
    SceneCase c;
    Synthetic s = write_synthetic(c.data());
    s.model.cameras.at(1).params[0] = f;
    colmap::write_model_binary(s.model, c.data() / "sparse/0");
    const std::string e = c.load_error();
    EXPECT_CONTAINS(e, (c.data() / "sparse/0/cameras.bin").string() + ": camera 1 (PINHOLE): focal length");
    EXPECT_CONTAINS(e, "must be a positive number of pixels");
  }
}

TEST(HostileScene, AHugeDistortionSaysTheLensIsWrongNotTheDownscale) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data(), CameraModelId::OpenCV);
  s.model.cameras.at(1).params[4] = 1e6;  // k1
  colmap::write_model_binary(s.model, c.data() / "sparse/0");
  const std::string e = c.load_error();
  EXPECT_CONTAINS(e, "camera 1 (OPENCV)");
  EXPECT_CONTAINS(e, "distortion");
  EXPECT_EQ(e.find("--downscale"), std::string::npos) << e;
}

TEST(HostileScene, IdenticalPosesAreRefusedForLackOfBaseline) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data());
  for (auto& [id, im] : s.model.images)
    im.qvec_wxyz = s.model.images.at(1).qvec_wxyz, im.tvec = s.model.images.at(1).tvec;
  colmap::write_model_binary(s.model, c.data() / "sparse/0");
  EXPECT_CONTAINS(c.load_error(), "cameras sit at one position, so there is no baseline");
}

TEST(HostileScene, TranslationsInOtherUnitsThanThePointsAreRefused) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data());
  for (auto& [id, im] : s.model.images)
    for (double& t : im.tvec) t *= 1e15;
  colmap::write_model_binary(s.model, c.data() / "sparse/0");
  EXPECT_CONTAINS(c.load_error(), "not in the same units");
}

TEST(HostileScene, CamerasThatSeeNoPointAreRefused) {
  SceneCase c;
  Synthetic s = write_synthetic(c.data());
  for (auto& [id, p] : s.model.points) p.xyz = {p.xyz[0], p.xyz[1] + 50.0, p.xyz[2]};  // far above every view
  colmap::write_model_binary(s.model, c.data() / "sparse/0");
  EXPECT_CONTAINS(c.load_error(), "cameras sees any of the 20 sparse points");
}

// ---- Training data ------------------------------------------------------------------------

TEST(HostileTraining, AnAllBlackMaskIsRefusedNotScoredInfinite) {
  TrainingData data = desplat::test::synthetic_training_data(5, 64, 48, 2);
  data.test[0].keep.assign(size_t(64) * 48, 0);
  TrainConfig cfg = desplat::test::short_schedule(10);
  cfg.distractors.enabled = false;
  EXPECT_CONTAINS(message_of([&] { Trainer t(data, cfg); }), "view view_0: its mask keeps no pixel");
}

TEST(HostileTraining, DistractorCountsBeyondThePixelsOrTheMemoryAreRefused) {
  const Camera cam = desplat::test::look_at_camera(0.5f, 1.0f, 100, 80);
  DistractorSettings s;
  s.reference_pixels = 0;
  s.initial_count = 8000;  // exactly the pixels
  EXPECT_NO_THROW(check_initial_distractors({cam, cam}, s));
  s.initial_count = 8001;
  EXPECT_CONTAINS(message_of([&] { check_initial_distractors({cam}, s); }),
                  "8001 initial distractors per view is more than a 100x80 training view has pixels (8000)");
  // Within each view's pixels, but not the machine's memory: the figure is given.
  const Camera big = desplat::test::look_at_camera(0.5f, 1.0f, 20000, 20000);
  s.initial_count = 10000000;
  const std::vector<Camera> many(2000, big);
  EXPECT_CONTAINS(message_of([&] { check_initial_distractors(many, s); }), "GB, more than this machine's");
}

// ---- Bench grids --------------------------------------------------------------------------

TEST(HostileBench, GridOfTheWrongShapeSaysWhatIsExpected) {
  TempDir dir("hostile_grid");
  const fs::path grid = dir.path() / "grid.json";
  desplat::testing::spit(grid, R"({"scenes": ["s"], "runs": 5})");
  const std::string e = message_of([&] { read_bench_grid(grid); });
  EXPECT_CONTAINS(e, "\"runs\" must be a list of runs");
  EXPECT_EQ(e.find("unknown run setting ''"), std::string::npos) << e;
  desplat::testing::spit(grid, R"({"scenes": "s", "runs": [{"name": "a"}]})");
  EXPECT_CONTAINS(message_of([&] { read_bench_grid(grid); }), "\"scenes\" must be a list of scene folders");
  desplat::testing::spit(grid, R"({"scenes": ["s"], "runs": [3]})");
  EXPECT_CONTAINS(message_of([&] { read_bench_grid(grid); }), "each entry of \"runs\" must be an object");
  desplat::testing::spit(grid, R"({"scenes": ["s"], "steps": "many", "runs": [{"name": "a"}]})");
  EXPECT_CONTAINS(message_of([&] { read_bench_grid(grid); }), "\"steps\" has the wrong type");
}

}  // namespace
}  // namespace scene_test
