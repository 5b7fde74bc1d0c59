// The appearance model (docs/METHOD.md §10): its MLP's hand-written backward against finite
// differences of an independent double-precision forward, the rasterizer's two-stage forward
// and rgb_scale chain rule against an equivalent SH model, determinism across thread counts,
// checkpoints, and training under per-view exposure.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <set>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/io/scene.hpp"
#include "desplat/jobs/training_run.hpp"
#include "desplat/synth/synth.hpp"
#include "desplat/train/appearance.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/loss.hpp"
#include "desplat/train/open_sky.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "support/expect.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

// Hand-computed: three points on the x axis at −1, 0, 1 have mean 0 and |x| = 1, 0, 1, whose
// 97th percentile (index ⌊0.97·2⌋ = 1 of the sorted 0, 1, 1) is 1: x' = 0, 0.5, 1.
TEST(Appearance, FourierFeaturesOfAHandComputedCase) {
  const std::vector<float> means = {-1, 5, 0, 0, 5, 0, 1, 5, 0};
  const std::vector<float> z = fourier_features(means, 2);
  ASSERT_EQ(z.size(), 3u * 12);
  // axis 0, frequency 0 (2π·x'), then frequency 1 (4π·x'): sin, cos each.
  const float want[3][4] = {{0, 1, 0, 1}, {0, -1, 0, 1}, {0, 1, 0, 1}};
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(z[12 * i + k], want[i][k], 1e-6) << "point " << i << " feature " << k;
  // A constant axis (y = 5 everywhere, z = 0) has scale 1 and x' = 0.5: sin(π) = 0, cos(π) = −1.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(z[12 * i + 4], 0.0, 1e-6);
    EXPECT_NEAR(z[12 * i + 5], -1.0, 1e-6);
  }
}

// An independent scalar forward in double: (β, γ) = MLP(z, c̄, e); c̃ = max(γ ⊙ c + β, 0).
struct DoubleMlp {
  std::vector<int> sizes;
  std::vector<double> w;  // the same flat layout as AppearanceModel::mlp
  std::vector<double> run(const std::vector<double>& input) const {
    std::vector<double> x = input;
    size_t at = 0;
    for (size_t l = 0; l + 1 < sizes.size(); ++l) {
      const int in = sizes[l], out = sizes[l + 1];
      std::vector<double> y(out);
      for (int r = 0; r < out; ++r) {
        double s = w[at + size_t(out) * in + r];  // bias after the matrix
        for (int c = 0; c < in; ++c) s += w[at + size_t(r) * in + c] * x[c];
        y[r] = l + 2 < sizes.size() ? std::max(s, 0.0) : s;
      }
      at += size_t(out) * (in + 1);
      x = y;
    }
    return x;
  }
};

struct Fixture {
  AppearanceModel model;
  GaussianSet g;
  RasterOutput fw;
  std::vector<double> weight;  // L = Σ weight · c̃ over visible rows
};

Fixture make_fixture(int n, unsigned seed) {
  AppearanceSettings s;
  s.enabled = true;
  s.image_dim = 4, s.fourier_frequencies = 1, s.hidden_width = 8, s.hidden_layers = 2;
  Fixture f;
  f.model = AppearanceModel(s, 3, seed);
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  // The last layer starts at zero; a trained one does not: exercise every layer.
  for (float& w : f.model.mlp) w = 0.6f * normal(rng);
  for (float& e : f.model.image_embeddings) e = normal(rng);
  f.g.sh_degree = 1;
  f.g.feature_dim = s.feature_dim();
  f.g.resize(size_t(n));
  for (float& v : f.g.colors) v = normal(rng);
  for (float& v : f.g.features) v = normal(rng);
  f.fw.visible.assign(size_t(n), 1);
  f.fw.rgb.resize(3 * size_t(n));
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (float& c : f.fw.rgb) c = unit(rng);
  for (int i = 0; i < n; i += 5) f.fw.visible[size_t(i)] = 0;  // invisible rows get no change, no gradient
  for (int i = 0; i < 3 * n; ++i) f.weight.push_back(normal(rng));
  // Visible rows whose colour reaches no pixel (zero loss weight): backward leaves them out.
  for (int i = 2; i < n; i += 7) f.weight[3 * i] = f.weight[3 * i + 1] = f.weight[3 * i + 2] = 0.0;
  return f;
}

// The loss through the double reference, with parameters taken from `mlp`, `e`, the set.
double reference_loss(const Fixture& f, const std::vector<double>& mlp, const std::vector<double>& e,
                      const std::vector<double>& features, const std::vector<double>& dc) {
  DoubleMlp net{f.model.layer_sizes(), mlp};
  const int fd = f.g.feature_dim;
  double loss = 0;
  for (size_t i = 0; i < f.g.size(); ++i) {
    if (!f.fw.visible[i]) continue;
    std::vector<double> in;
    for (int k = 0; k < fd; ++k) in.push_back(features[i * fd + k]);
    for (int c = 0; c < 3; ++c) in.push_back(dc[3 * i + c]);
    in.insert(in.end(), e.begin(), e.end());
    const std::vector<double> o = net.run(in);
    for (int c = 0; c < 3; ++c) {
      const double toned = (1.0 + o[3 + c]) * f.fw.rgb[3 * i + c] + o[c];
      loss += f.weight[3 * i + c] * std::max(toned, 0.0);
    }
  }
  return loss;
}

template <class T>
std::vector<double> as_double(const std::vector<T>& v) {
  return {v.begin(), v.end()};
}

// The hand-written backward (float) against central differences of the double reference.
TEST(Appearance, BackwardMatchesFiniteDifferencesOfADoubleReference) {
  Fixture f = make_fixture(40, 3);
  const size_t view = 1;
  const std::span<const float> e = f.model.embedding(view);
  RasterOutput fw = f.fw;
  AppearancePass pass;
  pass.forward(f.model, e, f.g, fw, 1);
  // The forward agrees with the reference, and some channels are clamped (the case matters).
  int clamped = 0;
  for (size_t i = 0; i < f.g.size(); ++i)
    for (int c = 0; c < 3; ++c) clamped += f.fw.visible[i] && fw.rgb[3 * i + c] == 0.0f;
  EXPECT_GT(clamped, 3);
  RasterGradients grads;
  grads.rgb.assign(3 * f.g.size(), 0.0f);
  for (size_t k = 0; k < grads.rgb.size(); ++k) grads.rgb[k] = float(f.weight[k]);
  grads.colors.assign(f.g.colors.size(), 0.0f);
  pass.backward(f.model, e, f.g, grads, 1);

  std::vector<double> mlp = as_double(f.model.mlp), emb = as_double(std::vector<float>(e.begin(), e.end()));
  std::vector<double> feat = as_double(f.g.features), dc(3 * f.g.size());
  const int stride = f.g.view().color_floats_per_gaussian();
  for (size_t i = 0; i < f.g.size(); ++i)
    for (int c = 0; c < 3; ++c) dc[3 * i + c] = f.g.colors[i * stride + c];
  const double h = 1e-6;
  auto central = [&](double& x) {
    const double keep = x;
    x = keep + h;
    const double up = reference_loss(f, mlp, emb, feat, dc);
    x = keep - h;
    const double down = reference_loss(f, mlp, emb, feat, dc);
    x = keep;
    return (up - down) / (2 * h);
  };
  auto close = [](double got, double want) { return std::abs(got - want) <= 2e-3 * (1 + std::abs(want)); };
  for (size_t k = 0; k < mlp.size(); ++k) {
    const double want = central(mlp[k]);
    ASSERT_TRUE(close(pass.d_mlp[k], want)) << "weight " << k << ": " << pass.d_mlp[k] << " vs " << want;
  }
  for (size_t k = 0; k < emb.size(); ++k) {
    const double want = central(emb[k]);
    ASSERT_TRUE(close(pass.d_embedding[k], want)) << "embedding " << k << ": " << pass.d_embedding[k] << " vs " << want;
  }
  for (size_t k = 0; k < feat.size(); ++k) {
    const double want = central(feat[k]);
    ASSERT_TRUE(close(grads.features[k], want)) << "feature " << k << ": " << grads.features[k] << " vs " << want;
  }
  for (size_t i = 0; i < f.g.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double want = central(dc[3 * i + c]);
      ASSERT_TRUE(close(grads.colors[i * stride + c], want)) << "DC " << i << "," << c;
    }
  // Invisible rows: colour untouched, no gradient.
  for (size_t i = 0; i < f.g.size(); i += 5) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(fw.rgb[3 * i + c], f.fw.rgb[3 * i + c]);
    for (int k = 0; k < f.g.feature_dim; ++k) EXPECT_EQ(grads.features[i * f.g.feature_dim + k], 0.0f);
  }
}

// A new model (last layer zero) renders the plain colours: γ = 1, β = 0.
TEST(Appearance, ANewModelLeavesTheColoursUnchanged) {
  Fixture f = make_fixture(20, 4);
  f.model = AppearanceModel(f.model.settings, 3, 4);
  RasterOutput fw = f.fw;
  AppearancePass pass;
  pass.forward(f.model, f.model.embedding(0), f.g, fw, 1);
  EXPECT_EQ(fw.rgb, f.fw.rgb);
}

// More rows than one slab holds: the same bits with 1 and 2 threads.
TEST(Appearance, ForwardAndBackwardAreBitIdenticalAcrossThreadCounts) {
  Fixture f = make_fixture(9000, 5);
  std::vector<float> rgb[2], d_mlp[2], d_e[2], d_feat[2];
  for (int t : {1, 2}) {
    RasterOutput fw = f.fw;
    AppearancePass pass;
    pass.forward(f.model, f.model.embedding(2), f.g, fw, t);
    RasterGradients grads;
    grads.rgb.assign(fw.rgb.size(), 0.0f);
    for (size_t k = 0; k < grads.rgb.size(); ++k) grads.rgb[k] = float(f.weight[k]);
    grads.colors.assign(f.g.colors.size(), 0.0f);
    pass.backward(f.model, f.model.embedding(2), f.g, grads, t);
    rgb[t - 1] = fw.rgb, d_mlp[t - 1] = pass.d_mlp, d_e[t - 1] = pass.d_embedding, d_feat[t - 1] = grads.features;
  }
  EXPECT_EQ(rgb[0], rgb[1]);
  EXPECT_EQ(d_mlp[0], d_mlp[1]);
  EXPECT_EQ(d_e[0], d_e[1]);
  EXPECT_EQ(d_feat[0], d_feat[1]);
}

TEST(Appearance, MismatchedSizesAreClearErrors) {
  Fixture f = make_fixture(10, 6);
  RasterOutput fw = f.fw;
  AppearancePass pass;
  const std::vector<float> short_embedding(3, 0.0f);
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { pass.forward(f.model, short_embedding, f.g, fw, 1); }),
                  "the image embedding has 3 values, the model expects 4");
  GaussianSet no_features = f.g;
  no_features.feature_dim = 0;
  no_features.features.clear();
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>(
                      [&] { pass.forward(f.model, f.model.embedding(0), no_features, fw, 1); }),
                  "carry 0 features each, the model expects 6");
  AppearanceSettings bad = f.model.settings;
  bad.hidden_width = 0;
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { bad.validate(); }),
                  "appearance.hidden_width must be > 0");
}

// The two-stage forward is the one-stage forward; rgb_scale is the chain rule. Reference: the
// colour change c̃ = 0.5·c is the SH model with coefficients c'_k = 0.5·c_k (k ≥ 1) and
// c'_0 = 0.5·c_0 − 0.25/Y₀, rendered and differentiated by the plain rasterizer; the gradient
// with respect to c is then 0.5 × that with respect to c', and the geometry's is the same.
TEST(Appearance, RasterizerStagesAndRgbScaleMatchAnEquivalentShModel) {
  const TrainingData data = synthetic_training_data(4, 48, 40, 8);
  GaussianSet g = ground_truth_scene(60, 8);
  g.sh_degree = 1;
  g.colors.resize(g.size() * 12, 0.0f);
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(0.9f, 1.6f), small(-0.05f, 0.05f);
  for (size_t i = 0; i < g.size(); ++i)
    for (int k = 0; k < 12; ++k) g.colors[12 * i + k] = k < 3 ? u(rng) : small(rng);  // bright: no clamp
  const Camera& cam = data.train[0].camera;
  RasterSettings rs;
  rs.num_threads = 1;
  RasterOutput one, two;
  rasterize_forward(g.view(), cam, rs, one);
  rasterize_project(g.view(), cam, rs, two);
  rasterize_blend(cam, rs, two);
  EXPECT_EQ(one.color, two.color);
  EXPECT_EQ(one.alpha, two.alpha);

  GaussianSet half = g;
  for (size_t i = 0; i < g.size(); ++i)
    for (int k = 0; k < 12; ++k)
      half.colors[12 * i + k] =
          k < 3 ? float(0.5 * g.colors[12 * i + k] - 0.25 / kShBand0) : 0.5f * g.colors[12 * i + k];
  RasterOutput scaled, reference;
  rasterize_project(g.view(), cam, rs, scaled);
  for (float& c : scaled.rgb) c *= 0.5f;
  rasterize_blend(cam, rs, scaled);
  rasterize_forward(half.view(), cam, rs, reference);
  for (size_t p = 0; p < reference.color.size(); ++p) ASSERT_NEAR(scaled.color[p], reference.color[p], 1e-5);

  std::vector<float> d_color(reference.color.size());
  std::normal_distribution<float> normal(0.0f, 1.0f);
  for (float& d : d_color) d = normal(rng);
  const std::vector<float> rgb_scale(3 * g.size(), 0.5f);
  RasterGradients got, want;
  rasterize_backward(g.view(), cam, rs, scaled, d_color, {}, {}, got, rgb_scale);
  rasterize_backward(half.view(), cam, rs, reference, d_color, {}, {}, want);
  for (size_t k = 0; k < got.colors.size(); ++k)
    ASSERT_NEAR(got.colors[k], 0.5f * want.colors[k], 1e-4 * (1 + std::abs(want.colors[k]))) << "colour " << k;
  for (size_t k = 0; k < got.means.size(); ++k)
    ASSERT_NEAR(got.means[k], want.means[k], 1e-3 * (1 + std::abs(want.means[k]))) << "mean " << k;
  // grads.rgb is ∂L/∂c̃: for the reference, whose c' = c̃, it is the same quantity.
  for (size_t k = 0; k < got.rgb.size(); ++k) ASSERT_NEAR(got.rgb[k], want.rgb[k], 1e-4 * (1 + std::abs(want.rgb[k])));
}

TrainConfig appearance_config(int64_t iterations) {
  TrainConfig c = short_schedule(iterations);
  c.random_background = false;
  c.distractors.enabled = false;
  c.appearance.enabled = true;
  c.appearance.hidden_width = 16;
  c.appearance.test_steps = 40;
  return c;
}

// Per-view exposure and white balance: each view's photo is the truth times a gain per
// channel (the known answer: one affine colour change per image explains it exactly).
TrainingData exposed_views(unsigned seed) {
  TrainingData data = synthetic_training_data(16, 64, 48, seed);
  std::mt19937 rng(seed + 7);
  std::uniform_real_distribution<float> stops(-1.0f, 1.0f), wb(-0.1f, 0.1f);
  for (auto* views : {&data.train, &data.test})
    for (TrainView& v : *views) {
      const float gain = std::exp2(stops(rng));
      const float channel[3] = {gain * (1 + wb(rng)), gain * (1 + wb(rng)), gain * (1 + wb(rng))};
      FloatImage photo = to_float(v.image);
      for (size_t p = 0; p < photo.pixels.size(); ++p) photo.pixels[p] *= channel[p % 3];
      v.image = to_bytes(photo);  // clipped at 1 and rounded, as a camera would
    }
  return data;
}

// The target of item 3 in miniature: under per-view exposure, the appearance model fits the
// training photos and, by the Photo Tourism protocol, the test views much better than none.
TEST(Appearance, ExposureChangesAreLearnedAndTestViewsScoredByTheProtocol) {
  const TrainingData data = exposed_views(12);
  TrainConfig with = appearance_config(600), without = with;
  without.appearance.enabled = false;
  Trainer a(data, with), b(data, without);
  for (int i = 0; i < 600; ++i) a.step(), b.step();
  const std::vector<ViewMetrics> ma = a.evaluate(data.test), mb = b.evaluate(data.test);
  double pa = 0, pb = 0;
  for (size_t v = 0; v < ma.size(); ++v) {
    EXPECT_EQ(ma[v].protocol, EvalProtocol::appearance_halves);
    EXPECT_EQ(mb[v].protocol, EvalProtocol::full_image);
    EXPECT_EQ(ma[v].look.appearance.size(), size_t(with.appearance.image_dim));
    pa += ma[v].psnr / ma.size(), pb += mb[v].psnr / mb.size();
  }
  EXPECT_GT(pa, pb + 3.0) << "appearance " << pa << " dB, none " << pb << " dB";
  // The per-Gaussian features grew with the Gaussians (densification copies rows).
  EXPECT_EQ(a.gaussians().params.features.size(), a.gaussians().size() * size_t(with.appearance.feature_dim()));
  a.mutable_gaussians().check_consistent();
}

// The Photo Tourism fit's start (appearance.test_start_from_best_look), against a brute force
// written here: each training look rendered through the public render() and scored by the
// photometric loss on the left half; the fit must start from the argmin.
std::vector<float> left_half(const Camera& cam) {
  std::vector<float> left(size_t(cam.width) * cam.height, 0.0f);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width / 2; ++x) left[size_t(y) * cam.width + x] = 1.0f;
  return left;
}

std::string brute_force_best_look(const Trainer& t, const Camera& cam, const FloatImage& photo,
                                  const TrainConfig& cfg) {
  const std::vector<float> left = left_half(cam);
  double best = std::numeric_limits<double>::infinity();
  std::string name;
  for (size_t j = 0; j < t.data().train.size(); ++j) {
    const FloatImage img = t.render(cam, cfg.eval_background, t.training_look(j));
    const double loss =
        photometric_loss(img.pixels, photo.pixels, cam.width, cam.height, cfg.ssim_lambda, {}, left).loss;
    if (loss < best) best = loss, name = t.data().train[j].name;
  }
  return name;
}

TEST(Appearance, TheFitStartsFromTheTrainingLookThatFitsTheLeftHalfBest) {
  const TrainingData data = exposed_views(15);
  const TrainConfig cfg = appearance_config(200);
  ASSERT_TRUE(cfg.appearance.test_start_from_best_look);  // the default
  Trainer t(data, cfg);
  for (int i = 0; i < 200; ++i) t.step();
  std::set<std::string> starts;
  for (const TrainView& v : data.test) {
    const ViewLook look = t.fit_look(v, left_half(v.camera));
    EXPECT_EQ(look.start, brute_force_best_look(t, v.camera, to_float(v.image), cfg)) << v.name;
    starts.insert(look.start);
  }
  EXPECT_GT(starts.size(), 1u);  // the test views do not all start alike: the choice is exercised

  // A view larger than kLookSearchPixels is judged on a copy halved until it fits: the test
  // view at 4× (pixels repeated), judged at 2× (128 px across), as the brute force at 2× says.
  const TrainView& v = data.test.front();
  TrainView big = v;
  big.camera.fx *= 4, big.camera.fy *= 4, big.camera.cx *= 4, big.camera.cy *= 4;
  big.camera.width *= 4, big.camera.height *= 4;
  big.image = ByteImage{big.camera.width, big.camera.height, 3, {}};
  big.image.pixels.resize(size_t(big.camera.width) * big.camera.height * 3);
  ASSERT_EQ(v.image.channels, 3);
  for (int y = 0; y < big.camera.height; ++y)
    for (int x = 0; x < big.camera.width; ++x)
      for (int c = 0; c < 3; ++c)
        big.image.pixels[(size_t(y) * big.camera.width + x) * 3 + c] =
            v.image.pixels[(size_t(y / 4) * v.camera.width + x / 4) * 3 + c];
  ASSERT_GT(std::max(big.camera.width, big.camera.height), kLookSearchPixels);
  const Camera judged = downscale_camera(big.camera, 2);
  ASSERT_LE(std::max(judged.width, judged.height), kLookSearchPixels);
  EXPECT_EQ(t.data().train[t.best_training_look(big, left_half(big.camera))].name,
            brute_force_best_look(t, judged, to_float(downscale_bytes(big.image, 2)), cfg));

  // Off (--preset paper): the mean look.
  TrainConfig off = appearance_config(20);
  off.appearance.test_start_from_best_look = false;
  Trainer m(data, off);
  for (int i = 0; i < 20; ++i) m.step();
  EXPECT_EQ(m.fit_look(v, left_half(v.camera)).start, "mean");
}

// Resuming an appearance model continues bit-exactly; a checkpoint that does not fit the run
// (appearance off, other sizes) is refused with what differs.
TEST(Appearance, ResumeIsBitExactAndMismatchesAreRefused) {
  const TrainingData data = exposed_views(13);
  const TrainConfig cfg = appearance_config(260);
  Trainer straight(data, cfg);
  for (int i = 0; i < 260; ++i) straight.step();
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("desplat_appearance_resume_" + std::to_string(::getpid()) + ".ckpt");
  {
    Trainer first(data, cfg);
    for (int i = 0; i < 155; ++i) first.step();
    write_checkpoint(file, make_training_checkpoint(first));
  }
  const Checkpoint ckpt = read_checkpoint(file);
  std::filesystem::remove(file);
  Trainer resumed(data, cfg);
  restore_training_checkpoint(resumed, ckpt);
  for (int i = 155; i < 260; ++i) resumed.step();
  EXPECT_EQ(straight.gaussians().params.features, resumed.gaussians().params.features);
  EXPECT_EQ(straight.gaussians().params.colors, resumed.gaussians().params.colors);
  EXPECT_EQ(straight.appearance().mlp, resumed.appearance().mlp);
  EXPECT_EQ(straight.appearance().image_embeddings, resumed.appearance().image_embeddings);
  EXPECT_EQ(straight.appearance().mlp_v, resumed.appearance().mlp_v);

  TrainConfig off = cfg;
  off.appearance.enabled = false;
  Trainer no_look(data, off);
  EXPECT_CONTAINS(testing::error_of<CheckpointError>([&] { restore_training_checkpoint(no_look, ckpt); }),
                  "trained with the appearance model but this run has it off");
  TrainConfig wider = cfg;
  wider.appearance.hidden_width = 32;
  Trainer other(data, wider);
  EXPECT_CONTAINS(testing::error_of<CheckpointError>([&] { restore_training_checkpoint(other, ckpt); }),
                  "2 hidden layers of 16; this run asks for 32, 24, 2 of 32");
}

// The training threads do not change an appearance model's bits.
TEST(Appearance, TrainingIsBitIdenticalAcrossThreadCounts) {
  const TrainingData data = exposed_views(14);
  TrainConfig one = appearance_config(120), two = one;
  one.threads = 1, two.threads = 2;
  Trainer a(data, one), b(data, two);
  for (int i = 0; i < 120; ++i) a.step(), b.step();
  EXPECT_EQ(a.gaussians().params.features, b.gaussians().params.features);
  EXPECT_EQ(a.gaussians().params.means, b.gaussians().params.means);
  EXPECT_EQ(a.appearance().mlp, b.appearance().mlp);
}

// A desplat_synth capture (bench.json at 160×120, 24 views, no distractors), loaded as training
// runs load it: real tracks (points with the views that see them).

}  // namespace
}  // namespace desplat::test
