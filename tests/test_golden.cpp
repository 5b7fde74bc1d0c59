// Regression suite: fixed-seed, fixed-thread (2) renders and short training runs
// compared with golden values stored in tests/golden/golden.json.
//
// Tolerances are two-sided, so a change that alters results in either direction fails
// and updating the goldens is always a deliberate step:
//   DESPLAT_UPDATE_GOLDEN=1 ./build/release/tests/test_golden
// rewrites the file; review the diff and say why in the commit (tests/golden/README.md).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>

#include "support/scenes.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

using json = nlohmann::json;
const std::string kGoldenPath = std::string(DESPLAT_SOURCE_DIR) + "/tests/golden/golden.json";

// Render values: float32 results on one instruction set are reproducible bit for
// bit; 1e-4 per thumbnail pixel absorbs libm differences between machines while any
// change to the kernel's semantics moves pixels by far more.
constexpr double kThumbTolerance = 1e-4;
// Training: 200 steps of a deterministic run; metric tolerances cover libm
// differences only (a real change to training moves PSNR by tenths of a dB).
constexpr double kPsnrTolerance = 0.05, kSsimTolerance = 0.002, kThumbTrainTolerance = 2e-3;

bool updating() { return std::getenv("DESPLAT_UPDATE_GOLDEN") != nullptr; }

json& golden() {
  static json j = [] {
    std::ifstream f(kGoldenPath);
    json g = json::object();
    if (f) f >> g;
    return g;
  }();
  return j;
}

void save_golden() { std::ofstream(kGoldenPath) << golden().dump(1) << "\n"; }

// 8×6 block means of an image, per channel.
std::vector<double> thumbnail(const FloatImage& img) {
  std::vector<double> t(8 * 6 * 3, 0.0);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const int bx = x * 8 / img.width, by = y * 6 / img.height;
        t[(by * 8 + bx) * 3 + c] += img.pixels[(size_t(y) * img.width + x) * 3 + c] * 48.0 / (img.width * img.height);
      }
  return t;
}

void check_thumbnail(const std::string& key, const std::vector<double>& got, double tolerance) {
  if (updating()) {
    golden()[key] = got;
    return;
  }
  ASSERT_TRUE(golden().contains(key)) << "no golden value '" << key << "' in " << kGoldenPath;
  const std::vector<double> want = golden()[key].get<std::vector<double>>();
  ASSERT_EQ(want.size(), got.size());
  for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], tolerance) << key << "[" << i << "]";
}

void check_value(const std::string& key, double got, double tolerance) {
  if (updating()) {
    golden()[key] = got;
    return;
  }
  ASSERT_TRUE(golden().contains(key)) << "no golden value '" << key << "' in " << kGoldenPath;
  EXPECT_NEAR(got, golden()[key].get<double>(), tolerance)
      << key << " moved; if intended, update the goldens (see tests/golden/README.md)";
}

TEST(Golden, KernelRenders) {
  for (int seed : {1, 2}) {
    std::mt19937 rng(seed);
    const Camera cam = random_camera(rng, 96, 72, 80);
    SceneSpec spec;
    spec.count = 400;
    const GaussianSet g = random_gaussians(rng, spec);
    RasterSettings s;
    s.num_threads = 2;
    RasterOutput out;
    rasterize_forward(g.view(), cam, s, out);
    FloatImage img{cam.width, cam.height, 3, out.color};
    check_thumbnail("kernel_render_" + std::to_string(seed), thumbnail(img), kThumbTolerance);
    FloatImage alpha{cam.width, cam.height, 3, {}};
    for (float a : out.alpha) alpha.pixels.insert(alpha.pixels.end(), {a, a, a});
    check_thumbnail("kernel_alpha_" + std::to_string(seed), thumbnail(alpha), kThumbTolerance);
  }
  if (updating()) save_golden();
}

// The portable build (DESPLAT_NATIVE=OFF) compiles everything but the pixel loops for baseline
// x86-64, without fused multiply-adds; over 200 steps that rounding moves test PSNR far outside
// the tolerance, so it has its own training goldens. Kernel renders are shared: the
// pixel loops pick their instruction set at run time in both builds.
std::string training_key(const std::string& name) {
  return std::string(DESPLAT_GOLDEN_BUILD) == "portable" ? "portable_" + name : name;
}

TEST(Golden, ShortTrainingRun) {
  const TrainingData data = synthetic_training_data(16, 64, 48, 11);
  TrainConfig c;
  c.iterations = 200;
  c.sh_degree = 1;
  c.sh_degree_interval = 100;
  c.resolution_schedule = 60;
  c.densify.warmup = 100;
  c.densify.refine_every = 50;
  c.random_background = false;
  c.threads = 2;
  c.seed = 3;
  c.distractors.enabled = false;  // the static baseline's regression values
  Trainer trainer(data, c);
  for (int i = 0; i < 200; ++i) trainer.step();
  double psnr = 0, ssim = 0;
  for (const auto& m : trainer.evaluate(data.test))
    psnr += m.psnr / data.test.size(), ssim += m.ssim / data.test.size();
  check_value(training_key("train_200_test_psnr"), psnr, kPsnrTolerance);
  check_value(training_key("train_200_test_ssim"), ssim, kSsimTolerance);
  check_value(training_key("train_200_gaussians"), double(trainer.gaussians().size()),
              0.02 * trainer.gaussians().size());
  check_thumbnail(training_key("train_200_render_test0"),
                  thumbnail(trainer.render(data.test[0].camera, c.eval_background)), kThumbTrainTolerance);
  if (updating()) save_golden();
}

}  // namespace
}  // namespace desplat::test
