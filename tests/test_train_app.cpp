// desplat_train and desplat_render as a user runs them, on a synthetic scene folder.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>
#include <nlohmann/json.hpp>
#include <OpenImageIO/imageio.h>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/sfm/subprocess.hpp"
#include "desplat/synth/synth.hpp"
#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {
namespace fs = std::filesystem;

struct Outcome {
  int exit_code;
  std::string output;
};

Outcome run(const std::string& command) {
  // One log per process: ctest runs these tests as parallel processes.
  const fs::path log = fs::temp_directory_path() / ("desplat_app_test_" + std::to_string(::getpid()) + ".log");
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  std::string text;
  {
    std::ifstream f(log);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  fs::remove(log);  // nothing left behind in the temporary folder
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
}

// `single` equals the static column (the second of five) of a training figure row.
void expect_static_column(const FloatImage& row, const FloatImage& single) {
  ASSERT_EQ(row.width, 5 * single.width);
  ASSERT_EQ(row.height, single.height);
  for (int y = 0; y < single.height; ++y)
    for (int x = 0; x < single.width; ++x)
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(single.pixels[3 * (size_t(y) * single.width + x) + c],
                  row.pixels[3 * (size_t(y) * row.width + single.width + x) + c])
            << "pixel " << x << "," << y;
}

class TrainApp : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("desplat_app_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    const TrainingData data = synthetic_training_data(16, 64, 48, 21);
    write_scene_folder(root_ / "scene", data);
  }
  static void TearDownTestSuite() { fs::remove_all(root_); }
  static std::string train() { return std::string(DESPLAT_TRAIN_BIN) + " --data " + (root_ / "scene").string(); }
  static inline fs::path root_;
};

TEST_F(TrainApp, TrainsAndWritesEveryOutput) {
  const fs::path out = root_ / "out";
  // 200 distractors per view (the default density gives 16 on 64×48 images): enough that some
  // still cover their view after 120 steps, for the layer and mask checks below.
  const Outcome r = run(train() + " --out " + out.string() +
                        " --iterations 120 --threads 2 --log-every 40 --eval-every 60 --distractors-per-view 200 --effects distractors");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("120/120"), std::string::npos) << r.output;  // plain progress lines in a pipe
  // 120 steps end inside the default resolution schedule (full resolution from step 6,000).
  EXPECT_NE(r.output.find("never trains at full resolution (the resolution schedule reaches it at step 6000 of 120)"),
            std::string::npos)
      << r.output;
  // … and before the default's distractor seeding (from step 3,000).
  EXPECT_NE(r.output.find("warning: distractor seeding starts at step 3000 (distractors.seed_after), after this "
                          "run's 120 steps"),
            std::string::npos)
      << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["step"], 120);
  int evaluations = 0, curve_points = 0;
  for (const auto& h : metrics["history"]) evaluations += h["kind"] == "evaluation", curve_points += h["kind"] == "training";
  EXPECT_EQ(evaluations, 1);     // at step 60; the final one is the metrics' own
  EXPECT_EQ(curve_points, 120);  // the training curve: every step of a run this short
  EXPECT_GT(metrics["mean_psnr"].get<double>(), 15.0);
  const GaussianSet ply = read_gaussian_ply(out / "point_cloud.ply");
  EXPECT_EQ(ply.size(), metrics["gaussians"].get<size_t>());
  nlohmann::json config;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["train"]["iterations"], 120);
  EXPECT_EQ(config["train"]["lr"]["means"], 1.6e-4f);  // docs/METHOD.md defaults are written out

  // desplat_render re-renders the test views as the evaluation saw them.
  const fs::path renders = root_ / "renders";
  const Outcome rr = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + renders.string());
  ASSERT_EQ(rr.exit_code, 0) << rr.output;
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(out / "renders" / "test")) {
    const FloatImage side = read_image_rgb(entry.path());
    const FloatImage single = read_image_rgb(renders / entry.path().filename());
    ASSERT_EQ(side.width, 2 * single.width);
    for (int y = 0; y < single.height; ++y)
      for (int x = 0; x < single.width; ++x)
        for (int c = 0; c < 3; ++c)
          ASSERT_EQ(side.pixels[(size_t(y) * side.width + single.width + x) * 3 + c],
                    single.pixels[(size_t(y) * single.width + x) * 3 + c]);
    ++compared;
  }
  EXPECT_EQ(compared, 2);  // 16 views, every 8th held out
  // DeSplat is the default: every training view has a Fig. 2 row and its layers can be rendered.
  EXPECT_EQ(metrics["mode"], "desplat");
  EXPECT_EQ(metrics["cost"]["views_with_distractors"], 14);  // no refinement before step 500
  EXPECT_TRUE(fs::exists(out / "renders" / "train" / "view_1.png"));
  const fs::path layers = root_ / "layers";
  const Outcome lr = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + layers.string() +
                         " --layer distractor --views train --mask --alpha");
  ASSERT_EQ(lr.exit_code, 0) << lr.output;
  EXPECT_TRUE(fs::exists(layers / "view_1.png"));
  EXPECT_TRUE(fs::exists(layers / "view_1_mask.png"));
  EXPECT_FALSE(fs::exists(layers / "view_0.png"));  // a test view
  // --alpha writes straight RGBA: re-compositing it over the evaluation background gives the
  // plain layer image, and its alpha agrees with the mask (A_d > 0.5).
  const fs::path plain = root_ / "layers_plain";
  ASSERT_EQ(run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " + plain.string() +
                " --layer distractor --views view_1.png").exit_code, 0);
  OIIO::ImageSpec raw_file;  // the file's own straight values, as a viewer sees them
  raw_file.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open((layers / "view_1.png").string(), &raw_file);
  ASSERT_TRUE(in);
  ASSERT_EQ(in->spec().nchannels, 4);
  std::vector<float> rgba(size_t(in->spec().width) * in->spec().height * 4);
  ASSERT_TRUE(in->read_image(0, 0, 0, 4, OIIO::TypeDesc::FLOAT, rgba.data()));
  in->close();
  const FloatImage shown = read_image_rgb(plain / "view_1.png");
  const FloatImage mask = read_image_rgb(layers / "view_1_mask.png");
  const std::vector<float> bg = config["train"]["eval_background"].get<std::vector<float>>();
  ASSERT_EQ(rgba.size() / 4, shown.pixels.size() / 3);
  int covered = 0;
  for (size_t p = 0; p < rgba.size() / 4; ++p) {
    const float a = rgba[4 * p + 3];
    EXPECT_EQ(a > 0.5f, mask.pixels[3 * p] > 0.5f) << p;
    covered += a > 0.5f;
    for (int c = 0; c < 3; ++c)  // 8-bit PNGs: a few quantization steps
      ASSERT_NEAR(rgba[4 * p + c] * a + (1 - a) * bg[c], shown.pixels[3 * p + c], 3.0 / 255) << p;
  }
  EXPECT_GT(covered, 0);  // 120 steps: the initial distractors still cover part of the view
  // Test views have no distractors: asking for that layer there is one clear error.
  const Outcome bad_layer = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " +
                                renders.string() + " --layer distractor");
  EXPECT_EQ(bad_layer.exit_code, 1);
  EXPECT_NE(bad_layer.output.find("view 'view_0.png' is not a training view"), std::string::npos) << bad_layer.output;
}

std::string decode_base64(const std::string& text) {
  std::string out;
  uint32_t buffer = 0;
  int bits = 0;
  for (char ch : text) {
    const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const char* p = std::strchr(alphabet, ch);
    if (ch == '=' || !p || ch == 0) continue;
    buffer = buffer << 6 | uint32_t(p - alphabet);
    bits += 6;
    if (bits >= 8) out += char(buffer >> (bits -= 8) & 0xff);
  }
  return out;
}

// report.html opened as a person would, in a real browser (Debian's Chromium, headless): every
// image decodes, every plot draws, and the screenshot is a page with pictures in it, not a
// blank or text-only one. The page's own script records what it found on <body>.
TEST_F(TrainApp, ReportOpensInHeadlessChromiumWithEveryImageAndPlot) {
  const fs::path out = root_ / "report_run";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 300 --threads 2 --eval-every 100 --effects distractors");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("report.html (open it in a browser)"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(out / "report.html"));
  EXPECT_FALSE(fs::exists(out / ".report_tmp"));  // gnuplot's files are cleaned up

  ASSERT_TRUE(find_executable("chromium")) << "chromium is not installed: run scripts/install_deps.sh";
  const std::string browser =
      "timeout 120 chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync --user-data-dir=" +
      (root_ / "chromium-profile").string() + " --virtual-time-budget=5000 ";
  const std::string url = "file://" + fs::absolute(out / "report.html").string();
  const Outcome dom = run(browser + "--dump-dom " + url);
  ASSERT_EQ(dom.exit_code, 0) << dom.output;
  // 2 test views + 14 training-view rows; the five curves (no full-resolution step in 300, so
  // no step-time chart).
  EXPECT_NE(dom.output.find("data-images=\"16\""), std::string::npos) << dom.output.substr(0, 2000);
  EXPECT_NE(dom.output.find("data-broken-images=\"0\""), std::string::npos);
  EXPECT_NE(dom.output.find("data-plots=\"5\""), std::string::npos);
  EXPECT_NE(dom.output.find("data-viewer=\"ok\""), std::string::npos);  // WebGL2 drew the model

  // The 3D viewer drew the static model from the first test view's camera: its first frame,
  // averaged over 15×15 blocks (960×720 → 64×48), against our CPU rasterizer's render of that
  // view in renders/test/ (right half). Same Gaussians, same projection; they differ by the
  // viewer's global sort (ours is per tile) and its 0.3 px² dilation at 15× the resolution.
  const Outcome frame_dom = run(browser + "--dump-dom " + url + "#viewer-frame");
  const std::string key = "data-viewer-frame=\"data:image/png;base64,";
  const size_t at = frame_dom.output.find(key);
  ASSERT_NE(at, std::string::npos) << frame_dom.output.substr(0, 500);
  const size_t end = frame_dom.output.find('"', at + key.size());
  write_file_atomically(root_ / "viewer.png", decode_base64(frame_dom.output.substr(at + key.size(), end - at - key.size())));
  const FloatImage viewer = read_image_rgb(root_ / "viewer.png");
  ASSERT_EQ(viewer.width, 960);
  ASSERT_EQ(viewer.height, 720);
  const FloatImage side = read_image_rgb(out / "renders" / "test" / "view_0.png");  // the first test view
  const int w = side.width / 2, h = side.height;
  double mse = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        double mean = 0;
        for (int dy = 0; dy < 15; ++dy)
          for (int dx = 0; dx < 15; ++dx) mean += viewer.pixels[(size_t(y * 15 + dy) * 960 + x * 15 + dx) * 3 + c];
        const double d = mean / 225 - side.pixels[(size_t(y) * side.width + w + x) * 3 + c];
        mse += d * d;
      }
  const double viewer_psnr = -10 * std::log10(mse / (3.0 * w * h));
  std::printf("[   info   ] viewer's first frame against the CPU render: %.2f dB\n", viewer_psnr);
  // Measured 49.4 dB; a wrong projection, covariance, orientation or colour falls below 20, and
  // a wrong draw order of one Gaussian (the depth sort's bucket bug, fixed 2026-11-26) gave 27.3.
  EXPECT_GT(viewer_psnr, 35.0);

  const fs::path shot = root_ / "report.png";
  ASSERT_EQ(run(browser + "--window-size=1300,2600 --screenshot=" + shot.string() + " " + url).exit_code, 0);
  const FloatImage page = read_image_rgb(shot);
  ASSERT_EQ(page.width, 1300);
  std::set<uint32_t> colours;
  size_t coloured = 0;  // pixels that are not grey: plot lines, rendered images
  for (size_t p = 0; p < page.pixels.size() / 3; ++p) {
    uint32_t rgb24 = 0;
    float lo = 1, hi = 0;
    for (int c = 0; c < 3; ++c) {
      const float v = page.pixels[3 * p + c];
      rgb24 = rgb24 << 8 | uint32_t(std::lround(v * 255));
      lo = std::min(lo, v), hi = std::max(hi, v);
    }
    colours.insert(rgb24);
    coloured += hi - lo > 0.15f;
  }
  std::printf("[   info   ] screenshot: %zu colours, %zu coloured pixels\n", colours.size(), coloured);
  // A blank page has one colour and a text-only page a few dozen greys and no coloured pixel;
  // this one (measured: ~145,000 colours, ~364,000 coloured pixels) has the 3D view, the
  // renders and the plots' lines. The bounds sit two orders of magnitude below.
  EXPECT_GT(colours.size(), 1000u);
  EXPECT_GT(coloured, 5000u);
}

// A fresh run into a folder that holds an earlier run is refused (it would overwrite that
// model's checkpoint and leave its renders next to the new ones); --overwrite replaces
// exactly the run's outputs and leaves other files alone.
TEST_F(TrainApp, ReusedOutputFolderIsRefusedUnlessOverwritten) {
  const fs::path out = root_ / "reused";
  ASSERT_EQ(run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only").exit_code, 0);
  const std::string checkpoint = testing::slurp(out / "checkpoint.ckpt");
  ASSERT_FALSE(checkpoint.empty());
  std::ofstream(out / "renders" / "test" / "from_another_scene.png") << "stale";
  std::ofstream(out / "notes.txt") << "the user's";

  Outcome r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, out.string() + " already holds a training run's outputs");
  EXPECT_CONTAINS(r.output, "checkpoint.ckpt");
  EXPECT_CONTAINS(r.output, "--resume");
  EXPECT_CONTAINS(r.output, "--overwrite");
  EXPECT_EQ(testing::slurp(out / "checkpoint.ckpt"), checkpoint) << "the earlier model must be untouched";

  r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --resume --overwrite");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_CONTAINS(r.output, "--resume and --overwrite contradict each other");

  r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --static-only --overwrite --seed 9");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(out / "renders" / "test" / "from_another_scene.png"));
  EXPECT_TRUE(fs::exists(out / "notes.txt"));
  EXPECT_TRUE(fs::exists(out / "metrics.json"));
  EXPECT_NE(testing::slurp(out / "checkpoint.ckpt"), checkpoint);
}

TEST_F(TrainApp, StaticOnlyModelHasNoDistractorLayer) {
  const fs::path out = root_ / "static_only";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 30 --threads 2 --static-only");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["mode"], "static-only");
  EXPECT_EQ(metrics["cost"]["distractor_gaussians"], 0);
  // The Splatfacto baseline starts from every sparse point, whatever the default does.
  EXPECT_EQ(metrics["transient_points"]["action"], "keep");
  EXPECT_EQ(metrics["transient_points"]["points"], 0);
  const Outcome bad = run(std::string(DESPLAT_RENDER_BIN) + " --model " + out.string() + " --out " +
                          (root_ / "so_renders").string() + " --views train --mask");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("--mask needs a DeSplat model"), std::string::npos) << bad.output;
}

// A background model (docs/METHOD.md §11): the run says so, scores by the Photo Tourism
// protocol, and desplat_render --appearance shows a training view over that photo's own learned
// background, exactly as the training figure's static column does.
TEST_F(TrainApp, BackgroundModelRendersOverAPhotosOwnBackground) {
  const fs::path out = root_ / "sky";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 60 --threads 2 --effects distractors,background");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background model: embeddings of 32 per training image"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_EQ(metrics["protocol"], "per-image embeddings fitted on the left half, scored on the right half");
  EXPECT_EQ(metrics["mean_psnr_right_half"], metrics["mean_psnr"]);
  EXPECT_TRUE(metrics["median_step_seconds_full_resolution"].contains("background"));

  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + out.string();
  const Outcome ok = run(render + " --out " + (root_ / "sky_look").string() + " --views view_1.png --appearance view_1.png");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const FloatImage single = read_image_rgb(root_ / "sky_look" / "view_1.png");
  const FloatImage row = read_image_rgb(out / "renders" / "train" / "view_1.png");
  expect_static_column(row, single);
  // Negative control: over the evaluation colour it is another image.
  const Outcome plain = run(render + " --out " + (root_ / "sky_plain").string() + " --views view_1.png");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  EXPECT_NE(read_image_rgb(root_ / "sky_plain" / "view_1.png").pixels, single.pixels);
}

// Appearance and background together: the background reads the appearance embedding (the
// default, the authors' form), the checkpoint says so, and desplat_render --appearance draws
// the training figure's static column exactly, sky included.
TEST_F(TrainApp, SharedEmbeddingRendersAsTheTrainerDrewIt) {
  const fs::path out = root_ / "both";
  const Outcome r =
      run(train() + " --out " + out.string() + " --iterations 60 --threads 2 --effects distractors,appearance,background");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json config;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["train"]["background"]["share_appearance_embedding"], true);
  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + out.string();
  const Outcome ok = run(render + " --out " + (root_ / "both_look").string() + " --views view_1.png --appearance view_1.png");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  expect_static_column(read_image_rgb(out / "renders" / "train" / "view_1.png"),
                       read_image_rgb(root_ / "both_look" / "view_1.png"));
}

// --effects distractors,appearance: the run says which protocol scored the test views, and
// desplat_render --appearance NAME (from the checkpoint) draws the static layer exactly as the
// trainer drew it in NAME's figure row (renders/train, the view's own embedding).
TEST_F(TrainApp, AppearanceModelRendersInAPhotosLookAndSaysItsProtocol) {
  const fs::path out = root_ / "appearance";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 60 --threads 2 --effects distractors,appearance");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("appearance model: embeddings of 32 per training image"), std::string::npos) << r.output;
  nlohmann::json metrics, config;
  std::ifstream(out / "metrics.json") >> metrics;
  std::ifstream(out / "config.json") >> config;
  EXPECT_EQ(config["run"]["effects"], "distractors,appearance");
  EXPECT_EQ(metrics["protocol"], "per-image embeddings fitted on the left half, scored on the right half");
  for (const auto& v : metrics["views"]) EXPECT_EQ(v["protocol"], metrics["protocol"]);

  const std::string render = std::string(DESPLAT_RENDER_BIN) + " --model " + out.string();
  const Outcome ok = run(render + " --out " + (root_ / "look").string() + " --views view_1.png --appearance view_1.png");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const FloatImage single = read_image_rgb(root_ / "look" / "view_1.png");
  const FloatImage row = read_image_rgb(out / "renders" / "train" / "view_1.png");
  expect_static_column(row, single);
  // Negative control: the plain colours are another image.
  const Outcome plain_look = run(render + " --out " + (root_ / "plain").string() + " --views view_1.png");
  ASSERT_EQ(plain_look.exit_code, 0) << plain_look.output;
  EXPECT_NE(read_image_rgb(root_ / "plain" / "view_1.png").pixels, single.pixels);

  const Outcome test_view = run(render + " --out " + (root_ / "look2").string() + " --appearance view_0.png");
  EXPECT_EQ(test_view.exit_code, 1);
  EXPECT_NE(test_view.output.find("'view_0.png' is not a training view"), std::string::npos) << test_view.output;
  // The default is --effects auto: this capture has one exposure and no sky, so appearance and
  // background stay off, and the transient probe decides distractors (its answer on this
  // cloud of small blobs over a void is not a fact about the scene: tests/test_transient_probe.cpp
  // checks answers). The decision, its evidence in the log, config.json and metrics.json, and
  // the model trained must agree.
  const Outcome plain = run(train() + " --out " + (root_ / "no_look").string() + " --iterations 5 --threads 2");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  EXPECT_NE(plain.output.find("--effects auto: probing for transients"), std::string::npos) << plain.output;
  nlohmann::json auto_config, auto_metrics;
  std::ifstream(root_ / "no_look" / "config.json") >> auto_config;
  const nlohmann::json& evidence = auto_config["run"]["effects_evidence"];
  const bool transients = evidence["transients"]["transients"];
  const std::string chosen = transients ? "distractors" : "none";
  EXPECT_NE(plain.output.find("--effects auto: " + chosen + "\n"), std::string::npos) << plain.output;
  EXPECT_EQ(auto_config["run"]["effects"], chosen);
  EXPECT_EQ(auto_config["run"]["effects_chosen_by"], "auto");
  ASSERT_EQ(evidence["reasons"].size(), 3u);
  EXPECT_EQ(evidence["reasons"][0].get<std::string>().rfind(transients ? "distractors on: " : "distractors off: ", 0), 0u)
      << evidence["reasons"][0];
  EXPECT_EQ(evidence["transients"]["views"].size(), auto_config["scene"]["train_views"].size());
  std::ifstream(root_ / "no_look" / "metrics.json") >> auto_metrics;
  EXPECT_EQ(auto_metrics["effects"]["evidence"]["transients"], evidence["transients"]);
  EXPECT_EQ(auto_metrics["mode"], transients ? "desplat" : "static-only");
  // … and trains exactly the model that names that set.
  const Outcome named = run(train() + " --out " + (root_ / "named").string() + " --iterations 5 --threads 2 --effects " + chosen);
  ASSERT_EQ(named.exit_code, 0) << named.output;
  EXPECT_EQ(testing::slurp(root_ / "named" / "point_cloud.ply"), testing::slurp(root_ / "no_look" / "point_cloud.ply"));
  const Outcome none = run(std::string(DESPLAT_RENDER_BIN) + " --model " + (root_ / "no_look").string() + " --out " +
                           (root_ / "look3").string() + " --appearance view_1.png");
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_NE(none.output.find("was trained without an appearance or background model"), std::string::npos) << none.output;
  const Outcome resume = run(train() + " --out " + out.string() + " --iterations 80 --threads 2 --resume --effects distractors");
  EXPECT_EQ(resume.exit_code, 1);
  // The recorded settings are checked before the checkpoint is opened (restore_training_checkpoint's
  // own refusal is tested in test_appearance.cpp).
  EXPECT_NE(resume.output.find("changes 1 of them: appearance.enabled false (true in " + (out / "config.json").string()),
            std::string::npos)
      << resume.output;
}

// A scene with ground-truth masks: metrics.json scores every training view's distractor mask.
TEST_F(TrainApp, MetricsScoreDistractorMasksWhenTheSceneHasThem) {
  synth::GenerateOptions g;
  g.out = root_ / "masked_scene";
  const synth::GenerationReport scene =
      synth::generate_scene(synth::load_description(fs::path(DESPLAT_SOURCE_DIR) / "data/synthetic/tiny_distractors.json"), g);
  for (const std::string mode : {"", " --static-only"}) {
    const fs::path out = root_ / ("masked" + std::to_string(mode.size()));
    const Outcome r = run(std::string(DESPLAT_TRAIN_BIN) + " --data " + g.out.string() + " --out " + out.string() +
                          " --iterations 20 --threads 2" + mode);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("distractor masks: mean IoU"), std::string::npos) << r.output;
    nlohmann::json metrics;
    std::ifstream(out / "metrics.json") >> metrics;
    const nlohmann::json& masks = metrics["distractor_masks"];
    ASSERT_EQ(masks["views"].size(), size_t(scene.num_train));
    EXPECT_EQ(masks["occluded_views"], scene.cluttered_views.size());
    for (const auto& v : masks["views"]) {
      const bool cluttered = std::count(scene.cluttered_views.begin(), scene.cluttered_views.end(), v["name"]) > 0;
      EXPECT_EQ(v["truth_fraction"].get<double>() > 0, cluttered) << v["name"];
      if (!mode.empty()) {
        EXPECT_EQ(v["predicted_fraction"], 0.0);  // static-only predicts no distractors
      }
    }
    if (!mode.empty()) {
      EXPECT_EQ(masks["mean_iou"], 0.0);
    }
  }
}

TEST_F(TrainApp, InterruptWritesCheckpointAndResumeFinishes) {
  const fs::path out = root_ / "interrupted";
  // SIGINT after 3 s of a run far too long to finish.
  // (--effects names the set, so no transient probe runs before training.)
  const Outcome r = run("timeout --preserve-status -s INT 3 " + train() + " --out " + out.string() +
                        " --iterations 1000000 --threads 2 --effects distractors");
  ASSERT_EQ(r.exit_code, 130) << r.output;
  EXPECT_NE(r.output.find("interrupted at step"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(out / "checkpoint.ckpt"));
  // The default --effects auto resumes with the effects the model was trained with.
  const Outcome resumed = run(train() + " --out " + out.string() + " --iterations 150 --threads 2 --resume");
  // Either it resumed below 150 and finished, or the interrupted run had passed 150 already.
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resumed from"), std::string::npos) << resumed.output;
  EXPECT_NE(resumed.output.find("--effects auto: distractors, as this model was trained"), std::string::npos)
      << resumed.output;
  EXPECT_EQ(resumed.output.find("probing for transients"), std::string::npos) << resumed.output;
  EXPECT_TRUE(fs::exists(out / "metrics.json"));
}

// --resume continues with the settings config.json records: a run started with --preset fast
// and resumed without it goes on as fast (resolution_schedule 1000 against the default's
// 3000), a resume naming other settings is refused with each difference named and nothing
// written, and one naming the same settings goes through.
TEST_F(TrainApp, ResumeKeepsTheTrainedSettingsAndRefusesOtherOnes) {
  const fs::path out = root_ / "resume_settings";
  const std::string first = train() + " --out " + out.string() + " --threads 2 --effects distractors --preset fast";
  ASSERT_EQ(run(first + " --iterations 20").exit_code, 0);
  auto recorded = [&] {
    nlohmann::json c;
    std::ifstream(out / "config.json") >> c;
    return c;
  };
  ASSERT_EQ(recorded()["train"]["resolution_schedule"], 1000);
  const std::string checkpoint_before = desplat::testing::slurp(out / "checkpoint.ckpt");

  const Outcome refused = run(train() + " --out " + out.string() + " --resume --iterations 40 --preset paper");
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("--resume continues the model with the settings it was trained with"), std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find("resolution_schedule 3000 (1000 in " + (out / "config.json").string() + ")"),
            std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find(" more. Resume without settings options"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("started with --preset fast and effects distractors"), std::string::npos)
      << refused.output;
  EXPECT_EQ(refused.output.find("iterations 40"), std::string::npos) << refused.output;  // may change
  // One setting changed by a config file on top of the first run's preset: exactly that one.
  const fs::path one_change = root_ / "radius_005.json";
  write_file_atomically(one_change, R"({"densify": {"camera_path_radius": 0.05}})");
  const Outcome one = run(first + " --resume --iterations 40 --config " + one_change.string());
  EXPECT_EQ(one.exit_code, 1) << one.output;
  EXPECT_NE(one.output.find("changes 1 of them: densify.camera_path_radius 0.05 (0.08 in " +
                            (out / "config.json").string() + ")."),
            std::string::npos)
      << one.output;
  EXPECT_EQ(desplat::testing::slurp(out / "checkpoint.ckpt"), checkpoint_before);
  EXPECT_EQ(recorded()["train"]["iterations"], 20);

  const Outcome resumed = run(train() + " --out " + out.string() + " --resume --iterations 40");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resumed from"), std::string::npos) << resumed.output;
  EXPECT_NE(resumed.output.find("at step 20"), std::string::npos) << resumed.output;
  EXPECT_EQ(recorded()["train"]["resolution_schedule"], 1000);
  EXPECT_EQ(recorded()["train"]["iterations"], 40);
  EXPECT_EQ(recorded()["run"]["preset"], "fast");

  const Outcome same = run(first + " --resume --iterations 50");
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("at step 40"), std::string::npos) << same.output;
  EXPECT_EQ(same.output.find("records no value"), std::string::npos) << same.output;

  // A config.json from a build before a setting existed: the resume says which it defaults.
  nlohmann::json older = recorded();
  older["train"]["densify"].erase("camera_path_radius");
  write_file_atomically(out / "config.json", older.dump(2));
  const Outcome old_file = run(train() + " --out " + out.string() + " --resume --iterations 60");
  ASSERT_EQ(old_file.exit_code, 0) << old_file.output;
  EXPECT_NE(old_file.output.find("warning: " + (out / "config.json").string() +
                                 " records no value for 1 setting (densify.camera_path_radius)"),
            std::string::npos)
      << old_file.output;
  EXPECT_TRUE(recorded()["train"]["densify"].contains("camera_path_radius"));  // written back
}

TEST_F(TrainApp, NoTestViewsIsSaidNotScoredAsZero) {
  const fs::path out = root_ / "all_train";
  const Outcome r = run(train() + " --out " + out.string() + " --iterations 5 --threads 2 --split all-train");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no test views to score"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("test PSNR 0.00"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  EXPECT_TRUE(metrics["mean_psnr"].is_null());
  EXPECT_EQ(metrics["count"], 0);
}

// desplat_train --images runs structure from motion first; here a stand-in `colmap` on PATH
// "finds" the scene's own model, which holds 16 of the 17 photos. What SfM lost, and every
// step it took, must reach the log, metrics.json and report.html.
TEST_F(TrainApp, PhotosStructureFromMotionLostAreNamedInLogMetricsAndReport) {
  const fs::path photos = root_ / "photos", bin = root_ / "fake_colmap_bin", out = root_ / "from_photos";
  fs::create_directories(photos);
  for (const auto& e : fs::directory_iterator(root_ / "scene" / "images")) fs::copy_file(e.path(), photos / e.path().filename());
  fs::copy_file(root_ / "scene" / "images" / "view_1.png", photos / "extra.png");  // a photo no model holds
  write_file_atomically(photos / "notes.txt", "not a photo");
  fs::create_directories(bin);
  const std::string fake = "#!/bin/sh\nprev=\"\"\nfor a in \"$@\"; do [ \"$prev\" = --output_path ] && out=\"$a\"; "
                           "prev=\"$a\"; done\n[ \"$1\" = mapper ] && mkdir -p \"$out/0\" && cp " +
                           (root_ / "scene" / "sparse" / "0").string() + "/* \"$out/0/\"\nexit 0\n";
  write_file_atomically(bin / "colmap", fake);
  fs::permissions(bin / "colmap", fs::perms::owner_all);
  const Outcome r = run("PATH=" + bin.string() + ":$PATH " + std::string(DESPLAT_TRAIN_BIN) + " --images " +
                        photos.string() + " --out " + out.string() + " --iterations 10 --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("colmap defaults:   16 of 17 photos"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("extra.png: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("notes.txt: not a photo"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  const nlohmann::json& sfm = metrics["sfm"];
  EXPECT_EQ(sfm["registered"], 16);
  EXPECT_EQ(sfm["photos"], 17);
  ASSERT_EQ(sfm["unregistered_photos"].size(), 1u);
  EXPECT_EQ(sfm["unregistered_photos"][0]["photo"], "extra.png");
  ASSERT_EQ(sfm["attempts"].size(), 1u);  // 16 of 17 is above 90 %: no escalation
  EXPECT_EQ(sfm["attempts"][0]["step"], "colmap defaults");
  EXPECT_EQ(sfm["warning"], "");
  EXPECT_EQ(sfm["matching"], "exhaustive: 17 photos are few enough to match every pair");
  const std::string report = desplat::testing::slurp(out / "report.html");
  EXPECT_NE(report.find("<h2>Structure from motion</h2>"), std::string::npos);
  EXPECT_NE(report.find("<tr><th>matching</th><td>exhaustive: 17 photos are few enough"), std::string::npos);
  // The stand-in wrote no database, so the reason is that it could not be read.
  EXPECT_EQ(sfm["unregistered_photos"][0]["reason"], "not in the model (colmap's database could not be read)");
  EXPECT_NE(report.find("<tr><th>extra.png</th><td>not in the model (colmap&#39;s database could not be read)"),
            std::string::npos);
  EXPECT_NE(report.find("<tr><th>notes.txt</th><td>not a photo"), std::string::npos);
  EXPECT_NE(report.find("<td>colmap defaults</td><td>16</td>"), std::string::npos);
}

TEST_F(TrainApp, BadInputGivesOneClearError) {
  Outcome r = run(std::string(DESPLAT_TRAIN_BIN) + " --data " + (root_ / "nope").string() + " --out " +
              (root_ / "o1").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find((root_ / "nope").string()), std::string::npos) << r.output;
  const fs::path cfg = root_ / "bad.json";
  std::ofstream(cfg) << R"({"lr": {"meens": 0.1}})";
  r = run(train() + " --out " + (root_ / "o2").string() + " --config " + cfg.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("unknown setting 'lr.meens'"), std::string::npos) << r.output;
  r = run(train() + " --out " + (root_ / "o3").string() + " --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no checkpoint"), std::string::npos) << r.output;
  // A setting that would divide by zero, and options out of range: one line each, nothing trained.
  std::ofstream(cfg) << R"({"resolution_schedule": 0})";
  r = run(train() + " --out " + (root_ / "o4").string() + " --config " + cfg.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("resolution_schedule must be an integer in [1, 2147483647] (got 0)"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(root_ / "o4" / "checkpoint.ckpt"));
  // The same settings given as JSON text instead of a file, and a file that is not there.
  r = run(train() + " --out " + (root_ / "o4").string() + R"( --config '{"resolution_schedule": 0}')");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--config text: config: resolution_schedule must be an integer in [1, 2147483647] (got 0)"), std::string::npos)
      << r.output;
  r = run(train() + " --out " + (root_ / "o4").string() + R"( --config '{"seed": ')");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--config text is not valid JSON"), std::string::npos) << r.output;
  r = run(train() + " --out " + (root_ / "o4").string() + " --config " + (root_ / "absent.json").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find((root_ / "absent.json").string()), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(root_ / "o4" / "checkpoint.ckpt"));
  for (const auto& [option, message] : {std::pair{"--iterations 0", "--iterations: must be an integer in [1, 9223372036854775807] (got 0)"},
                                        {"--checkpoint-every -3", "--checkpoint-every: must be an integer in [0, 2147483647] (got -3)"},
                                        {"--eval-every -1", "--eval-every: must be an integer in [0, 2147483647] (got -1)"},
                                        {"--downscale 1000", "--downscale: must be an integer in [1, 64] (got 1000)"}}) {
    r = run(train() + " --out " + (root_ / "o5").string() + " " + option);
    EXPECT_NE(r.exit_code, 0) << option;
    EXPECT_NE(r.output.find(message), std::string::npos) << r.output;
  }
}

}  // namespace
}  // namespace desplat::test
