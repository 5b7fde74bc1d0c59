// The background model (docs/METHOD.md §11): the degree-4 harmonics against the sphere's
// inner product, the ray directions against the camera's projection, the MLP + harmonics
// backward against finite differences of an independent double-precision forward, L_bg on a
// hand-computed case, the per-pixel background's gradient through the composite, determinism,
// checkpoints, and training on a scene whose sky no Gaussian explains.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/io/checkpoint.hpp"
#include "desplat/train/background.hpp"
#include "desplat/train/loss.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "desplat/train/transient_probe.hpp"
#include "support/expect.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

// ∫ Y_i Y_j dΩ = δ_ij for all 25 functions of bands 0–4, by a Fibonacci lattice of 400,000
// points (equal areas 4π/N): a wrong constant or a sign slip inside a polynomial shows as an
// error of 0.05 or more; the lattice's own error is below 1e-4 here.
TEST(SphericalHarmonics, BandsUpToFourAreOrthonormalOnTheSphere) {
  constexpr int kN = 400000, kK = sh_coefficients(4);
  std::vector<double> gram(kK * kK, 0.0);
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int n = 0; n < kN; ++n) {
    const double z = 1.0 - (2.0 * n + 1.0) / kN, r = std::sqrt(1.0 - z * z), phi = golden * n;
    double Y[kK];
    sh_basis<double, 4>(4, r * std::cos(phi), r * std::sin(phi), z, Y);
    for (int i = 0; i < kK; ++i)
      for (int j = 0; j < kK; ++j) gram[i * kK + j] += Y[i] * Y[j] * (4.0 * M_PI / kN);
  }
  for (int i = 0; i < kK; ++i)
    for (int j = 0; j < kK; ++j) EXPECT_NEAR(gram[i * kK + j], i == j ? 1.0 : 0.0, 1e-3) << i << ", " << j;
}

// A lower degree fills only its own bands (the rest of Y is left alone).
TEST(SphericalHarmonics, ADegreeFillsOnlyItsBands) {
  float Y[25];
  std::fill(std::begin(Y), std::end(Y), -7.0f);
  sh_basis<float, 4>(2, 0.6f, 0.0f, 0.8f, Y);
  for (int k = 9; k < 25; ++k) EXPECT_EQ(Y[k], -7.0f) << k;
  EXPECT_NEAR(Y[2], 0.48860251 * 0.8, 1e-6);
}

// The camera maps a point along the pixel's ray back to that pixel.
TEST(Background, RayDirectionsPassThroughTheirPixelCentres) {
  const Camera cam = look_at_camera(0.7f, 1.0f, 40, 30);
  const std::array<float, 3> c = cam.center();
  for (int y = 0; y < cam.height; y += 7)
    for (int x = 0; x < cam.width; x += 5) {
      const std::array<float, 3> d = pixel_ray_direction(cam, x, y);
      EXPECT_NEAR(d[0] * d[0] + d[1] * d[1] + d[2] * d[2], 1.0, 1e-6);
      const std::array<float, 3> p{c[0] + 3 * d[0], c[1] + 3 * d[1], c[2] + 3 * d[2]};
      EXPECT_EQ(cam.pixel_of(p), (long long)y * cam.width + x) << x << ", " << y;
    }
}

// An independent double-precision forward: the MLP and bg(p) = 0.5 + Σ c_k Y_k(d_p).
std::vector<double> reference_background(const BackgroundModel& m, const std::vector<double>& mlp,
                                         const std::vector<double>& e, const Camera& cam, int degree) {
  const std::vector<int> sizes = m.layer_sizes();
  std::vector<double> in = e;
  size_t at = 0;
  for (size_t l = 0; l + 1 < sizes.size(); ++l) {
    const int n_in = sizes[l], n_out = sizes[l + 1];
    std::vector<double> out(n_out);
    for (int o = 0; o < n_out; ++o) {
      double s = mlp[at + size_t(n_out) * n_in + o];
      for (int i = 0; i < n_in; ++i) s += mlp[at + size_t(o) * n_in + i] * in[i];
      out[o] = l + 2 == sizes.size() ? s : std::max(s, 0.0);
    }
    at += size_t(n_out) * (n_in + 1);
    in = out;
  }
  std::vector<double> img;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      // The direction in double, from the camera's definition (not pixel_ray_direction).
      const double dc[3] = {(x + 0.5 - cam.cx) / cam.fx, (y + 0.5 - cam.cy) / cam.fy, 1.0};
      double d[3];
      for (int i = 0; i < 3; ++i) d[i] = cam.R_cw[i] * dc[0] + cam.R_cw[3 + i] * dc[1] + cam.R_cw[6 + i] * dc[2];
      const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      double Y[25];
      sh_basis<double, 4>(degree, d[0] / n, d[1] / n, d[2] / n, Y);
      for (int c = 0; c < 3; ++c) {
        double v = 0.5;
        for (int k = 0; k < sh_coefficients(degree); ++k) v += in[3 * k + c] * Y[k];
        img.push_back(v);
      }
    }
  return img;
}

struct Fixture {
  BackgroundSettings settings;
  BackgroundModel model;
  Camera cam = look_at_camera(1.3f, 1.0f, 12, 9);
  std::vector<float> weights;  // L = Σ w · bg
  Fixture() {
    settings.enabled = true;
    settings.image_dim = 5, settings.hidden_width = 7, settings.hidden_layers = 2;
    model = BackgroundModel(settings, 3, 11);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-0.5f, 0.5f);
    for (float& w : model.mlp) w = u(rng);  // the last layer too: every weight gets a gradient
    for (float& e : model.image_embeddings) e = 2 * u(rng);
    weights.resize(size_t(cam.width) * cam.height * 3);
    for (float& w : weights) w = u(rng);
  }
};

TEST(Background, ForwardMatchesTheDoubleReference) {
  Fixture f;
  BackgroundPass pass;
  pass.forward(f.model, f.model.embedding(1), f.cam, 4, 1);
  const std::vector<double> mlp(f.model.mlp.begin(), f.model.mlp.end());
  const std::span<const float> e = f.model.embedding(1);
  const std::vector<double> want = reference_background(f.model, mlp, {e.begin(), e.end()}, f.cam, 4);
  ASSERT_EQ(pass.image.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) EXPECT_NEAR(pass.image[i], want[i], 2e-5 * (1 + std::abs(want[i]))) << i;
}

// Every weight and every embedding value: the hand-written backward against central
// differences of the double reference (h = 1e-6; the MLP is piecewise linear, so away from
// a ReLU's kink the differences are exact up to rounding).
TEST(Background, BackwardMatchesFiniteDifferencesOfTheReference) {
  Fixture f;
  for (int degree : {0, 2, 4}) {
    BackgroundPass pass;
    pass.forward(f.model, f.model.embedding(2), f.cam, degree, 1);
    pass.d_image = f.weights;
    pass.backward(f.model, f.model.embedding(2), f.cam, 1);
    std::vector<double> mlp(f.model.mlp.begin(), f.model.mlp.end());
    const std::span<const float> ef = f.model.embedding(2);
    std::vector<double> e(ef.begin(), ef.end());
    auto loss = [&] {
      const std::vector<double> img = reference_background(f.model, mlp, e, f.cam, degree);
      double s = 0;
      for (size_t i = 0; i < img.size(); ++i) s += f.weights[i] * img[i];
      return s;
    };
    const double h = 1e-6;
    auto numeric = [&](double& x) {
      const double keep = x;
      x = keep + h;
      const double up = loss();
      x = keep - h;
      const double down = loss();
      x = keep;
      return (up - down) / (2 * h);
    };
    for (size_t i = 0; i < mlp.size(); ++i) {
      const double want = numeric(mlp[i]);
      EXPECT_NEAR(pass.d_mlp[i], want, 1e-3 * (1 + std::abs(want))) << "degree " << degree << " weight " << i;
    }
    for (size_t i = 0; i < e.size(); ++i) {
      const double want = numeric(e[i]);
      EXPECT_NEAR(pass.d_embedding[i], want, 1e-3 * (1 + std::abs(want))) << "degree " << degree << " embedding " << i;
    }
  }
}

TEST(Background, BackwardIsBitIdenticalForAnyThreadCount) {
  Fixture f;
  std::vector<float> first_mlp, first_e;
  for (int threads : {1, 2, 3}) {
    BackgroundPass pass;
    pass.forward(f.model, f.model.embedding(0), f.cam, 4, threads);
    pass.d_image = f.weights;
    pass.backward(f.model, f.model.embedding(0), f.cam, threads);
    if (threads == 1) {
      first_mlp = pass.d_mlp, first_e = pass.d_embedding;
      continue;
    }
    EXPECT_EQ(pass.d_mlp, first_mlp) << threads << " threads";
    EXPECT_EQ(pass.d_embedding, first_e) << threads << " threads";
  }
}

// A new model's last layer is zero: a uniform mid-grey, whatever the direction or photo.
TEST(Background, ANewModelIsUniformMidGrey) {
  BackgroundSettings s;
  s.enabled = true;
  const BackgroundModel m(s, 4, 3);
  BackgroundPass pass;
  pass.forward(m, m.embedding(3), look_at_camera(0.2f, 1.0f, 16, 12), 4, 2);
  for (float v : pass.image) EXPECT_EQ(v, 0.5f);
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>(
                      [&] { pass.forward(m, std::vector<float>(3, 0.0f), look_at_camera(0.2f, 1.0f, 16, 12), 4, 1); }),
                  "the image embedding has 3 values, the model expects 32");
}

// L_bg and its opaque counterpart by hand on a 4×3 image: columns 0–2 are explained (the photo equals the background),
// column 3 is not. A pixel is chosen when more than 0.6 of its 3×3 box (outside = not
// explained) is: (1,0), (0,1), (1,1), (2,1), (1,2) have 6, 6, 9, 6, 6 of 9; the corners of the
// explained block and column 3 have 4 or 3 or fewer.
TEST(Background, AlphaLossOfAHandComputedCase) {
  const int w = 4, h = 3;
  std::vector<float> bg(w * h * 3, 0.3f), target(w * h * 3, 0.3f);
  for (int y = 0; y < h; ++y)
    for (int c = 0; c < 3; ++c) target[(y * w + 3) * 3 + c] = 0.9f;
  target[(1 * w + 1) * 3] += 0.002f;  // mean error 0.0007 < 0.003: still explained
  std::vector<float> as(w * h), ad(w * h), sc(w * h * 3, 0.0f), dc(w * h * 3, 0.0f);
  for (int p = 0; p < w * h; ++p) as[p] = 0.1f * p / (w * h), ad[p] = 0.05f * (p % 3);
  BackgroundSettings s;
  std::vector<float> d_as(w * h, 0.0f);
  const double value = background_alpha_loss(bg, target, {sc, as}, {dc, ad}, w, h, s, d_as);
  // The five chosen pixels are pulled transparent by λ_bg = 0.15, the other seven opaque by λ_o = 0.01.
  std::vector<int> clear;
  for (const auto& xy : {std::pair{1, 0}, {0, 1}, {1, 1}, {2, 1}, {1, 2}}) clear.push_back(xy.second * w + xy.first);
  double sum_clear = 0, sum_covered = 0;
  std::vector<float> want(w * h, 0.0f);
  for (int p = 0; p < w * h; ++p) {
    const double a = ad[p] + (1 - ad[p]) * as[p];
    if (std::find(clear.begin(), clear.end(), p) != clear.end()) {
      sum_clear += a;
      want[p] = float(0.15 * (1 - ad[p]) / 5);
    } else {
      sum_covered += 1 - a;
      want[p] = float(-0.01 * (1 - ad[p]) / 7);
    }
  }
  EXPECT_NEAR(value, 0.15 * sum_clear / 5 + 0.01 * sum_covered / 7, 1e-7);
  for (int p = 0; p < w * h; ++p) EXPECT_NEAR(d_as[p], want[p], 1e-8) << "pixel " << p;
  // The user's mask: ignoring pixel (1,1) leaves its neighbours 5 of 9 (not clear) and (1,1)
  // in neither set: the other eleven are pulled opaque.
  std::vector<float> keep(w * h, 1.0f), d_keep(w * h, 0.0f);
  keep[1 * w + 1] = 0;
  double covered = 0;
  for (int p = 0; p < w * h; ++p)
    if (p != 1 * w + 1) covered += 1 - (ad[p] + (1 - ad[p]) * as[p]);
  EXPECT_NEAR(background_alpha_loss(bg, target, {sc, as}, {dc, ad}, w, h, s, d_keep, keep), 0.01 * covered / 11, 1e-7);
  EXPECT_EQ(d_keep[1 * w + 1], 0.0f);
  for (int p = 0; p < w * h; ++p) {
    if (p == 1 * w + 1) continue;
    EXPECT_NEAR(d_keep[p], -0.01 * (1 - ad[p]) / 11, 1e-8) << p;
  }
}

// ∂C/∂bg through the composite = (1 − A_d)(1 − A_s), 0 where the clamp holds.
TEST(Background, PerPixelBackgroundGradientThroughTheComposite) {
  const std::vector<float> cs = {0.2f, 0.1f, 0.3f, 0.99f, 0.9f, 0.9f}, as = {0.4f, 0.95f};
  const std::vector<float> cd = {0.1f, 0.0f, 0.2f, 0.0f, 0.0f, 0.0f}, ad = {0.3f, 0.0f};
  const std::vector<float> bg = {0.5f, 0.6f, 0.7f, 1.0f, 1.0f, 1.0f}, d_out = {1, 2, 3, 4, 5, 6};
  std::vector<float> out(6), g_cs(6), g_as(2), g_cd(6), g_ad(2), g_bg(6, -1.0f);
  composite_layers({cs, as}, {cd, ad}, Background(std::span<const float>(bg)), out);
  composite_layers_backward({cs, as}, {cd, ad}, Background(std::span<const float>(bg)), d_out,
                            {g_cs, g_as, g_cd, g_ad, g_bg});
  for (int p = 0; p < 2; ++p)
    for (int c = 0; c < 3; ++c) {
      const int i = 3 * p + c;
      const double raw = composite_unclamped<double>(cs[i], as[p], cd[i], ad[p], bg[i]);
      EXPECT_NEAR(out[i], std::clamp(raw, 0.0, 1.0), 1e-6);
      const double want = raw > 1.0 ? 0.0 : d_out[i] * (1.0 - ad[p]) * (1.0 - as[p]);
      EXPECT_NEAR(g_bg[i], want, 1e-6) << i;
    }
  EXPECT_EQ(g_bg[3], 0.0f);  // 0.99 + 0.05·1 > 1: the clamp holds, no gradient
  EXPECT_NEAR(g_bg[4], 5 * 0.05, 1e-6);
}

// The synthetic views of support/synthetic_views.hpp over a sky instead of a flat colour: blue
// overhead fading to pale at the horizon, brighter towards one side, per ray direction (world
// y is down in these cameras' frame), and per photo a little brighter or darker (haze).
TrainingData sky_views(unsigned seed) {
  TrainingData data = synthetic_training_data(16, 64, 48, seed);
  const GaussianSet truth = ground_truth_scene(120, seed);
  std::mt19937 rng(seed + 3);
  std::uniform_real_distribution<float> haze(-0.06f, 0.06f);
  for (auto* views : {&data.train, &data.test})
    for (TrainView& v : *views) {
      RasterOutput out;
      rasterize_forward(truth.view(), v.camera, RasterSettings{}, out);
      const float shift = haze(rng);
      FloatImage photo{v.camera.width, v.camera.height, 3, std::vector<float>(3 * out.alpha.size())};
      for (int y = 0; y < v.camera.height; ++y)
        for (int x = 0; x < v.camera.width; ++x) {
          const std::array<float, 3> d = pixel_ray_direction(v.camera, x, y);
          const float up = std::clamp(-d[1] * 2.0f + 0.3f, 0.0f, 1.0f), side = 0.1f * d[0];
          const float sky[3] = {0.85f - 0.55f * up + side + shift, 0.88f - 0.4f * up + side + shift,
                                0.95f - 0.1f * up + shift};
          const size_t p = size_t(y) * v.camera.width + x;
          for (int c = 0; c < 3; ++c) photo.pixels[3 * p + c] = out.color[3 * p + c] + (1 - out.alpha[p]) * sky[c];
        }
      v.image = to_bytes(photo);
    }
  return data;
}

// The target of item 2 in miniature: the background model learns a sky that no Gaussian
// explains, so the test views (Photo Tourism protocol for both) come out much better than
// the baseline's, whose sky must be painted by Gaussians or left at the evaluation colour.
TEST(Background, LearnsASkyThatNoGaussianExplains) {
  const TrainingData data = sky_views(21);
  TrainConfig with = short_schedule(600), without = with;
  with.distractors.enabled = without.distractors.enabled = false;
  with.background.enabled = true;
  with.appearance.test_steps = 40;
  Trainer a(data, with), b(data, without);
  for (int i = 0; i < 600; ++i) a.step(), b.step();
  const std::vector<ViewMetrics> ma = a.evaluate(data.test), mb = b.evaluate(data.test);
  double pa = 0, pb = 0;
  for (size_t v = 0; v < ma.size(); ++v) {
    EXPECT_EQ(ma[v].protocol, EvalProtocol::appearance_halves);
    EXPECT_EQ(ma[v].look.background.size(), size_t(with.background.image_dim));
    EXPECT_TRUE(ma[v].look.appearance.empty());
    pa += ma[v].psnr_right_half / ma.size(), pb += mb[v].psnr_right_half / mb.size();
  }
  EXPECT_GT(pa, pb + 3.0) << "background " << pa << " dB, none " << pb << " dB (right halves)";
  std::printf("background %.2f dB, none %.2f dB (right halves of the test views)\n", pa, pb);
}

// Resuming a background model continues bit-exactly; a checkpoint without one, or with other
// sizes, is refused with what differs.
TEST(Background, ResumeIsBitExactAndMismatchesAreRefused) {
  const TrainingData data = sky_views(22);
  TrainConfig cfg = short_schedule(240);
  cfg.distractors.enabled = false;
  cfg.background.enabled = true;
  cfg.background.hidden_width = 16;
  Trainer straight(data, cfg);
  for (int i = 0; i < 240; ++i) straight.step();
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("desplat_background_resume_" + std::to_string(::getpid()) + ".ckpt");
  {
    Trainer first(data, cfg);
    for (int i = 0; i < 130; ++i) first.step();
    write_checkpoint(file, make_training_checkpoint(first));
  }
  const Checkpoint ckpt = read_checkpoint(file);
  std::filesystem::remove(file);
  Trainer resumed(data, cfg);
  restore_training_checkpoint(resumed, ckpt);
  for (int i = 130; i < 240; ++i) resumed.step();
  EXPECT_EQ(straight.gaussians().params.colors, resumed.gaussians().params.colors);
  EXPECT_EQ(straight.background().mlp, resumed.background().mlp);
  EXPECT_EQ(straight.background().image_embeddings, resumed.background().image_embeddings);
  EXPECT_EQ(straight.background().embed_v, resumed.background().embed_v);

  TrainConfig off = cfg;
  off.background.enabled = false;
  Trainer without(data, off);
  EXPECT_CONTAINS(testing::error_of<CheckpointError>([&] { restore_training_checkpoint(without, ckpt); }),
                  "trained with the background model but this run has it off");
  TrainConfig wider = cfg;
  wider.background.hidden_width = 32;
  Trainer other(data, wider);
  EXPECT_CONTAINS(testing::error_of<CheckpointError>([&] { restore_training_checkpoint(other, ckpt); }),
                  "3 hidden layers of 16 and SH degree 4; this run asks for 32, 3 of 32 and 4");
}

// The shared embedding (background.share_appearance_embedding, the default) against an
// independent expectation: with the appearance MLP frozen at its start (last layer zero, so it
// leaves every colour unchanged and sends no gradient to the embedding), the background reading
// the appearance embedding must train bit for bit as a background that owns a copy of it. Then
// the shared run's own background embeddings never move, a test view's fitted look is one
// vector for both, and resuming is refused across the two forms.
TEST(Background, TheSharedEmbeddingTrainsAsTheBackgroundsOwnCopyWould) {
  const TrainingData data = sky_views(23);
  TrainConfig shared = short_schedule(150);
  shared.distractors.enabled = false;
  shared.background.enabled = shared.appearance.enabled = true;
  shared.background.hidden_width = 16;
  shared.appearance.hidden_width = 16;
  shared.appearance.lr_mlp = 0.0f;  // frozen: the appearance path adds nothing
  shared.appearance.test_steps = 5;
  TrainConfig own = shared;
  own.background.share_appearance_embedding = false;
  Trainer a(data, shared), b(data, own);
  ASSERT_TRUE(a.shared_embedding());
  ASSERT_FALSE(b.shared_embedding());
  const std::vector<float> unused = a.background().image_embeddings;
  b.mutable_background().image_embeddings = b.appearance().image_embeddings;  // the same start
  for (int i = 0; i < 150; ++i) a.step(), b.step();
  EXPECT_NE(a.appearance().image_embeddings, b.appearance().image_embeddings) << "the sky moved the shared one";
  EXPECT_EQ(a.appearance().image_embeddings, b.background().image_embeddings);
  EXPECT_EQ(a.background().mlp, b.background().mlp);
  EXPECT_EQ(a.gaussians().params.colors, b.gaussians().params.colors);
  EXPECT_EQ(a.background().image_embeddings, unused);
  for (const ViewMetrics& m : a.evaluate({data.test[0]})) {
    EXPECT_EQ(m.look.background, m.look.appearance);
    EXPECT_EQ(m.look.background.size(), size_t(shared.background.image_dim));
  }

  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("desplat_shared_embedding_" + std::to_string(::getpid()) + ".ckpt");
  write_checkpoint(file, make_training_checkpoint(a));
  const Checkpoint ckpt = read_checkpoint(file);
  std::filesystem::remove(file);
  Trainer other(data, own);
  EXPECT_CONTAINS(testing::error_of<CheckpointError>([&] { restore_training_checkpoint(other, ckpt); }),
                  "reads the appearance embeddings; this run's would read its own");
  TrainConfig narrow = shared;
  narrow.background.image_dim = 8;
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { Trainer t(data, narrow); }),
                  "background.image_dim (8) must equal appearance.image_dim (32)");
}

// --effects auto's probe judges each training view in the look it was trained with. With the
// shared embedding that is the appearance embedding for the sky too; the background's own copy
// is never trained, and a sky drawn from it is not the view's (the probe once read it).
TEST(Background, TheTransientProbeRendersAViewInItsTrainedLook) {
  const TrainingData data = sky_views(24);
  TrainConfig cfg = short_schedule(150);
  cfg.distractors.enabled = false;
  cfg.background.enabled = cfg.appearance.enabled = true;
  cfg.background.hidden_width = cfg.appearance.hidden_width = 16;
  Trainer t(data, cfg);
  ASSERT_TRUE(t.shared_embedding());
  for (int i = 0; i < 150; ++i) t.step();
  double stale_gap = 0;
  for (size_t v = 0; v < data.train.size(); v += 5) {
    const ProbeView pv = probe_view(t, v, 1);
    const auto e = t.appearance().embedding(v);
    ViewLook own;  // the view's look, stated here: its embedding for the scene and the sky alike
    own.appearance.assign(e.begin(), e.end());
    own.background = own.appearance;
    ViewLook stale = own;
    const auto b = t.background().embedding(v);
    stale.background.assign(b.begin(), b.end());
    const ByteImage& photo = data.train[v].image;
    const FloatImage want = t.render(data.train[v].camera, cfg.eval_background, own);
    const FloatImage wrong = t.render(data.train[v].camera, cfg.eval_background, stale);
    ASSERT_EQ(pv.error.size(), size_t(photo.width) * photo.height);
    for (size_t p = 0; p < pv.error.size(); ++p) {
      float sum = 0, stale_sum = 0;
      for (int c = 0; c < 3; ++c) {
        sum += std::fabs(want.pixels[3 * p + c] - byte_to_float(photo.pixels[3 * p + c]));
        stale_sum += std::fabs(wrong.pixels[3 * p + c] - byte_to_float(photo.pixels[3 * p + c]));
      }
      ASSERT_FLOAT_EQ(pv.error[p], sum / 3) << "view " << v << ", pixel " << p;
      stale_gap = std::max(stale_gap, double(std::fabs(stale_sum - sum) / 3));
    }
  }
  // The two looks differ on these photos, so the comparison above tells them apart.
  EXPECT_GT(stale_gap, 0.01);
}

}  // namespace
}  // namespace desplat::test
