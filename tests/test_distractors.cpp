// DeSplat's per-view distractor Gaussians: initialization (docs/METHOD.md §5), the refinement
// schedule and rules (§7), and their life inside the trainer (only their view touches them,
// emptied views cost nothing, ablation switches, checkpoints resume bit-exactly).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>

#include "desplat/train/distractors.hpp"
#include "desplat/train/init.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

std::array<double, 3> to_camera(const Camera& c, const float* x) {
  std::array<double, 3> p{};
  for (int r = 0; r < 3; ++r) {
    p[r] = c.t_cw[r];
    for (int k = 0; k < 3; ++k) p[r] += double(c.R_cw[3 * r + k]) * x[k];
  }
  return p;
}

TEST(Distractors, InitializedOnAPlaneInFrontOfTheirCamera) {
  const Camera cam = look_at_camera(0.7f, 1.0f, 64, 48);
  DistractorSettings s;
  s.reference_pixels = 0;  // exactly initial_count
  const GaussianSet g = init_distractors(cam, s, 42);
  ASSERT_EQ(g.size(), 1000u);
  EXPECT_EQ(g.color_mode, ColorMode::RGB);
  std::vector<std::array<float, 3>> xyz(g.size());
  double min_x = 1, max_x = -1;
  for (size_t i = 0; i < g.size(); ++i) {
    const std::array<double, 3> p = to_camera(cam, &g.means[3 * i]);
    EXPECT_NEAR(p[2], 0.02, 1e-6);
    EXPECT_LE(std::abs(p[0]), 0.01 + 1e-6);
    EXPECT_LE(std::abs(p[1]), 0.01 + 1e-6);
    min_x = std::min(min_x, p[0]), max_x = std::max(max_x, p[0]);
    for (int k = 0; k < 3; ++k) xyz[i][k] = g.means[3 * i + k];
    EXPECT_NEAR(1 / (1 + std::exp(-g.opacity_logits[i])), 0.1, 1e-6);
    for (int c = 0; c < 3; ++c) EXPECT_TRUE(g.colors[3 * i + c] >= 0 && g.colors[3 * i + c] <= 1);
    double qn = 0;
    for (int k = 0; k < 4; ++k) qn += g.quats[4 * i + k] * g.quats[4 * i + k];
    EXPECT_NEAR(qn, 1.0, 1e-5);
  }
  EXPECT_LT(min_x, -0.009);  // the plane is filled, not a point
  EXPECT_GT(max_x, 0.009);
  // Scales: brute-force mean distance to the 3 nearest others, in double.
  for (size_t i = 0; i < g.size(); i += 97) {
    std::vector<double> d;
    for (size_t j = 0; j < g.size(); ++j) {
      if (j == i) continue;
      double s2 = 0;
      for (int k = 0; k < 3; ++k) s2 += std::pow(double(xyz[i][k]) - xyz[j][k], 2);
      d.push_back(std::sqrt(s2));
    }
    std::partial_sort(d.begin(), d.begin() + 3, d.end());
    const double want = std::log((d[0] + d[1] + d[2]) / 3);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(g.log_scales[3 * i + k], want, 1e-4) << i;
  }
  EXPECT_EQ(init_distractors(cam, s, 42).means, g.means);  // deterministic
  EXPECT_NE(init_distractors(cam, s, 43).means, g.means);
  s.initial_count = 0;
  EXPECT_EQ(init_distractors(cam, s, 1).size(), 0u);
  s.initial_count = -1;
  EXPECT_THROW(init_distractors(cam, s, 1), std::invalid_argument);
}

TEST(Distractors, DefaultCountKeepsThePapersDensityOnTheImage) {
  DistractorSettings s;  // 1,000 for a 504×378 image
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 504, 378), s), 1000);
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 252, 189), s), 250);
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 1008, 756), s), 4000);
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 64, 48), s), 16);  // 1000 · 3072 / 190512
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 4, 3), s), 1);     // never rounds to none
  EXPECT_EQ(init_distractors(look_at_camera(0.7f, 1.0f, 64, 48), s, 7).size(), 16u);
  s.initial_count = 0;
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 504, 378), s), 0);
  s.initial_count = 300, s.reference_pixels = 0;  // a fixed count
  EXPECT_EQ(distractor_count_for(look_at_camera(0.7f, 1.0f, 64, 48), s), 300);
  s.reference_pixels = -1;
  EXPECT_THROW(distractor_count_for(look_at_camera(0.7f, 1.0f, 64, 48), s), std::invalid_argument);
}

TEST(Distractors, RefinementScheduleIsEveryFewEpochsUntilTheEnd) {
  // The default's 3 epochs and the authors' 10 (--preset paper), 43 views: periods of 129 and
  // 430 steps, refined at the first multiple of 100 in each window.
  DensifySettings d;
  const int views = 43;
  for (const int epochs : {3, 10}) {
    DistractorSettings s;
    s.refine_every_epochs = epochs;
    const int64_t period = int64_t(epochs) * views;
    std::vector<int64_t> due;
    for (int64_t step = 0; step < 20000; ++step)
      if (distractor_refine_due(step, views, d, s)) due.push_back(step);
    std::vector<int64_t> want;
    for (int64_t step = d.warmup + 1; step < 20000; ++step)
      if (step % 100 == 0 && step % period < 100) want.push_back(step);
    EXPECT_EQ(due, want) << epochs << " epochs";
    ASSERT_GE(due.size(), 2u);
    // 10 epochs: 860 is not a multiple of 100, 900 % 430 = 40. 3 epochs: 600 % 129 = 84.
    EXPECT_EQ(due[0], epochs == 10 ? 900 : 600);
    EXPECT_TRUE(distractor_refine_due(19800, views, d, s));  // culling continues after 15,000
    s.density_control = false;
    EXPECT_FALSE(distractor_refine_due(due[0], views, d, s));
  }
  EXPECT_EQ(DistractorSettings{}.refine_every_epochs, 3);
}

// Four distractors with hand-set statistics: seen and sharp (kept), never seen (culled),
// transparent (culled), high gradient and large (split before 15,000, kept after).
TEST(Distractors, RefineCullsUnseenAndDensifiesOnlyBefore15000) {
  auto make = [] {
    GaussianSet g;
    g.color_mode = ColorMode::RGB;
    g.resize(4);
    for (size_t i = 0; i < 4; ++i) {
      g.opacity_logits[i] = 2.0f;
      for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(0.005f), g.colors[3 * i + k] = 0.5f;
    }
    g.opacity_logits[2] = -5.0f;
    for (int k = 0; k < 3; ++k) g.log_scales[9 + k] = std::log(0.05f);
    TrainableGaussians t(g);
    t.visible_count = {10, 0, 10, 10};
    t.absgrad_sum = {0.0f, 0.0f, 0.0f, 10.0f};
    t.max_screen_radius = {0.01f, 0.0f, 0.01f, 0.01f};
    t.statistics_empty = false;
    return t;
  };
  DensifySettings d;
  std::mt19937_64 rng(1);
  TrainableGaussians before = make();
  const RefineReport r = refine_distractors(before, d, DistractorSettings{}, 5000, 100, rng);
  EXPECT_EQ(r.split, 1);
  EXPECT_EQ(r.culled, 2);             // unseen + transparent
  EXPECT_EQ(before.size(), 1u + 2u);  // the kept one + 2 split samples
  EXPECT_FALSE(r.opacity_reset);
  TrainableGaussians after = make();
  const RefineReport r2 = refine_distractors(after, d, DistractorSettings{}, 16000, 100, rng);
  EXPECT_EQ(r2.split + r2.duplicated, 0);
  EXPECT_EQ(r2.culled, 2);
  EXPECT_EQ(after.size(), 2u);
  after.check_consistent();
}

// The split threshold at the distractors' depth: size_threshold 0.01 at a scene depth of 1.6
// is 0.01 · 0.02 / 1.6 = 1.25e-4 world units for distractors at ρ = 0.02.
TEST(Distractors, SplitThresholdIsTheStaticAngleAtTheirDepth) {
  DensifySettings d;
  DistractorSettings s;
  EXPECT_FALSE(s.size_threshold_at_scene_depth);  // measured, off by default
  EXPECT_FLOAT_EQ(distractor_size_threshold(d, s, 1.6), 0.01f);
  s.size_threshold_at_scene_depth = true;
  EXPECT_NEAR(distractor_size_threshold(d, s, 1.6), 1.25e-4, 1e-9);
  EXPECT_FLOAT_EQ(distractor_size_threshold(d, s, 0.0), 0.01f);  // no points: the world threshold

  // Two seen distractors with a high gradient, max scales 3e-4 (above 1.25e-4) and 1e-4 (below).
  auto make = [] {
    GaussianSet g;
    g.color_mode = ColorMode::RGB;
    g.resize(2);
    for (size_t i = 0; i < 2; ++i) {
      g.opacity_logits[i] = 2.0f;
      for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(i == 0 ? 3e-4f : 1e-4f);
    }
    TrainableGaussians t(g);
    t.visible_count = {10, 10};
    t.absgrad_sum = {10.0f, 10.0f};
    t.max_screen_radius = {0.01f, 0.01f};
    t.statistics_empty = false;
    return t;
  };
  std::mt19937_64 rng(1);
  TrainableGaussians at_depth = make();
  const RefineReport r = refine_distractors(at_depth, d, s, 5000, 100, rng, kUnlimitedGrowth, 1.6);
  // The large one splits into 2 samples at 3e-4 / 1.6 = 1.875e-4 (still above the threshold,
  // so not duplicated as well); the small one is duplicated.
  EXPECT_EQ(r.split, 1);
  EXPECT_EQ(r.duplicated, 1);
  EXPECT_EQ(at_depth.size(), 1u + 2u + 1u);  // the small one, 2 split samples, 1 copy
  float largest = 0;
  for (size_t i = 0; i < at_depth.size(); ++i) largest = std::max(largest, std::exp(at_depth.params.log_scales[3 * i]));
  EXPECT_NEAR(largest, 1.875e-4f, 1e-8f);  // nothing keeps the old 3e-4
  TrainableGaussians world = make();
  const RefineReport w = refine_distractors(world, d, DistractorSettings{}, 5000, 100, rng, kUnlimitedGrowth, 1.6);
  EXPECT_EQ(w.split, 0);  // off (the default): both far below 0.01, duplicated at full size
  EXPECT_EQ(w.duplicated, 2);
  EXPECT_EQ(world.size(), 4u);
}

TrainConfig desplat_config(int64_t iterations) {
  TrainConfig c = short_schedule(iterations);
  c.distractors.initial_count = 200;
  c.distractors.reference_pixels = 0;  // 200 per view even on these tiny images
  return c;
}

// Parameters of every distractor buffer, to compare before and after a step.
std::vector<std::vector<float>> all_distractor_params(const Trainer& t) {
  std::vector<std::vector<float>> out;
  for (const TrainableGaussians& d : t.distractors()) {
    std::vector<float> p;
    for (int g = 0; g < kParamGroups; ++g)
      p.insert(p.end(), d.param(ParamGroup(g)).begin(), d.param(ParamGroup(g)).end());
    out.push_back(p);
  }
  return out;
}

TEST(DistractorTraining, OnlyTheStepsViewTouchesItsDistractors) {
  const TrainingData data = synthetic_training_data(8, 64, 48, 5);
  Trainer t(data, desplat_config(20));
  ASSERT_EQ(t.distractors().size(), data.train.size());
  EXPECT_EQ(t.distractor_count(), 200 * data.train.size());
  for (int i = 0; i < 12; ++i) {
    const auto before = all_distractor_params(t);
    const int64_t pos = t.view_order_pos;
    const StepStats st = t.step();
    const int view = t.view_order[pos < int64_t(t.view_order.size()) ? pos : 0];
    const auto after = all_distractor_params(t);
    EXPECT_EQ(st.view_distractors, 200u);
    EXPECT_GT(st.timings.distractor, 0.0);
    for (size_t v = 0; v < after.size(); ++v)
      if (int(v) == view)
        EXPECT_NE(before[v], after[v]) << "step " << i;
      else
        EXPECT_EQ(before[v], after[v]) << "step " << i << " view " << v;
    EXPECT_EQ(t.distractors()[view].adam_step, (i / int(data.train.size())) + 1);
  }
}

TEST(DistractorTraining, AnEmptiedViewCostsNothing) {
  const TrainingData data = synthetic_training_data(8, 64, 48, 5);
  Trainer t(data, desplat_config(20));
  TrainableGaussians& d0 = t.mutable_distractors()[0];
  d0.keep(std::vector<uint8_t>(d0.size(), 0));
  for (int i = 0; i < int(data.train.size()) * 2; ++i) {
    const int64_t pos = t.view_order_pos;
    const StepStats st = t.step();
    if (t.view_order[pos % int64_t(t.view_order.size())] == 0 && pos < int64_t(t.view_order.size())) {
      EXPECT_EQ(st.view_distractors, 0u);
      EXPECT_EQ(st.timings.distractor, 0.0);  // no rasterization, no optimizer work
    }
  }
  // A refinement hands an emptied view's memory back.
  TrainConfig c = desplat_config(600);
  c.distractors.reseed_starved_views = false;  // a starved view would be re-seeded, and cost again
  c.distractors.seed_uncovered = false;        // so would a view whose residual is uncovered
  c.distractors.initial_count = 30;
  c.distractors.init_opacity = 0.01f;  // all below the cull threshold: the first refinement empties every view
  Trainer t2(data, c);
  bool emptied = false;
  for (int i = 0; i < 200 && !emptied; ++i) {
    t2.step();
    emptied = t2.distractor_count() == 0;
  }
  ASSERT_TRUE(emptied);
  for (const TrainableGaussians& d : t2.distractors()) {
    EXPECT_EQ(d.params.means.capacity(), 0u);
    EXPECT_EQ(d.adam_m[0].capacity(), 0u);
  }
  for (int i = 0; i < 10; ++i) EXPECT_EQ(t2.step().timings.distractor, 0.0);
}

TEST(DistractorTraining, AblationSwitches) {
  const TrainingData data = synthetic_training_data(8, 64, 48, 5);
  TrainConfig off = desplat_config(10);
  off.distractors.enabled = false;
  EXPECT_TRUE(Trainer(data, off).distractors().empty());

  TrainConfig no_density = desplat_config(300);
  no_density.distractors.density_control = false;
  Trainer t(data, no_density);
  for (int i = 0; i < 300; ++i) t.step();
  for (const TrainableGaussians& d : t.distractors()) EXPECT_EQ(d.size(), 200u);

  // Regularizers: with λ = 0 the reported loss is the photometric loss alone; the
  // difference is λ_s·mean(1 − A_s) + λ_d·mean(A_d) ≥ 0 on the same step.
  TrainConfig with = desplat_config(5), without = desplat_config(5);
  without.distractors.regularize = false;
  with.distractors.lambda_static = 0.5f;
  Trainer a(data, with), b(data, without);
  const double la = a.step().loss, lb = b.step().loss;
  EXPECT_GT(la, lb + 1e-4);
}

TEST(DistractorTraining, NonFiniteDistractorIsPrunedWithItsViewNamed) {
  const TrainingData data = synthetic_training_data(8, 64, 48, 5);
  Trainer t(data, desplat_config(20));
  std::vector<std::string> warnings;
  t.warn = [&](const std::string& m) { warnings.push_back(m); };
  for (auto& d : t.mutable_distractors()) d.params.colors[3 * 5] = NAN;
  const int64_t pos = t.view_order_pos;
  t.step();
  const int view = t.view_order[pos < int64_t(t.view_order.size()) ? pos : 0];
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find(data.train[view].name), std::string::npos) << warnings[0];
  EXPECT_EQ(t.distractors()[view].size(), 199u);
  for (float v : t.distractors()[view].params.colors) EXPECT_TRUE(std::isfinite(v));
}

TEST(DistractorTraining, ResumeReproducesUninterruptedRunBitExactly) {
  const TrainingData data = synthetic_training_data(6, 64, 48, 7);
  TrainConfig cfg = desplat_config(380);
  cfg.densify.warmup = 50;
  Trainer straight(data, cfg);
  for (int i = 0; i < 380; ++i) straight.step();

  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("desplat_distractor_resume_" + std::to_string(::getpid()) + ".ckpt");
  {
    Trainer first(data, cfg);
    for (int i = 0; i < 155; ++i) first.step();  // after distractor refinements, mid-epoch
    write_checkpoint(file, make_training_checkpoint(first));
  }
  Trainer resumed(data, cfg);
  restore_training_checkpoint(resumed, read_checkpoint(file));
  for (int i = 155; i < 380; ++i) resumed.step();

  EXPECT_EQ(all_distractor_params(straight), all_distractor_params(resumed));
  for (size_t v = 0; v < straight.distractors().size(); ++v) {
    EXPECT_EQ(straight.distractors()[v].adam_v, resumed.distractors()[v].adam_v);
    EXPECT_EQ(straight.distractors()[v].adam_step, resumed.distractors()[v].adam_step);
  }
  for (int g = 0; g < kParamGroups; ++g)
    EXPECT_EQ(straight.gaussians().param(ParamGroup(g)), resumed.gaussians().param(ParamGroup(g)));
  // The run refined distractors (counts changed) before and after the checkpoint.
  EXPECT_NE(straight.distractor_count(), 200 * data.train.size());

  // A static-only run cannot take this checkpoint (and the reverse): clear errors.
  TrainConfig static_cfg = cfg;
  static_cfg.distractors.enabled = false;
  Trainer static_trainer(data, static_cfg);
  try {
    restore_training_checkpoint(static_trainer, read_checkpoint(file));
    ADD_FAILURE() << "expected an error";
  } catch (const CheckpointError& e) {
    EXPECT_NE(std::string(e.what()).find("distractors for"), std::string::npos) << e.what();
  }
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace desplat::test
