// A batch of training views per optimizer step (docs/METHOD.md §6, batches): the summed static
// gradient against the single-view gradients rendered by hand, its order of sums (the view
// tree) against the ranks', the batched Adam rule against the update computed in double, the
// schedules at equal views seen, and the per-view updates of distractors and appearance
// embeddings.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <set>
#include <utility>

#include "desplat/raster/composite.hpp"
#include "desplat/train/batch.hpp"
#include "desplat/train/distractors.hpp"
#include "desplat/train/loss.hpp"
#include "desplat/train/train_config_json.hpp"
#include "support/synthetic_views.hpp"

namespace desplat::test {
namespace {

// The static gradient of one view's photometric loss over a fixed background, by the public
// raster and loss stages (what the trainer's pass does without distractors or per-image models).
RasterGradients single_view_gradient(const GaussianSet& g, const TrainView& v, const TrainConfig& c) {
  RasterSettings rs;
  rs.num_threads = 1;
  rs.active_sh_degree = c.sh_degree_at(0);
  RasterOutput fw;
  rasterize_forward(g.view(), v.camera, rs, fw);
  const size_t pixels = size_t(v.camera.width) * v.camera.height;
  const Background bg(c.eval_background);
  std::vector<float> composite(3 * pixels), d_composite(3 * pixels), d_color(3 * pixels), d_alpha(pixels);
  const Layer statics{fw.color, fw.alpha};
  composite_layers(statics, Layer{}, bg, composite);
  const FloatImage photo = to_float(v.image);
  photometric_loss(composite, photo.pixels, v.camera.width, v.camera.height, c.ssim_lambda, d_composite);
  composite_layers_backward(statics, Layer{}, bg, d_composite, {d_color, d_alpha, {}, {}});
  RasterGradients grads;
  rasterize_backward(g.view(), v.camera, rs, fw, d_color, d_alpha, {}, grads);
  return grads;
}

TrainConfig static_batch_config(int batch, int64_t iterations) {
  TrainConfig c = short_schedule(iterations);
  c.batch = batch;
  c.distractors.enabled = false;
  c.random_background = false;  // the evaluation colour: a background the test can rebuild
  c.num_downscales = 0;
  return c;
}

TEST(Batch, OneStepsStaticGradientIsTheSumOfItsViewsGradients) {
  const TrainingData data = synthetic_training_data(8, 40, 30, 3);
  const int batch = 4;
  const TrainConfig c = static_batch_config(batch, 100);
  Trainer t(data, c);
  const GaussianSet before = t.gaussians().params;
  t.step();
  ASSERT_EQ(t.current_step(), batch);
  ASSERT_EQ(t.gaussians().size(), before.size());  // no refinement at the first views
  // The views of the batch: the first `batch` of the epoch's order.
  std::vector<double> expected(before.means.size(), 0.0);
  for (int b = 0; b < batch; ++b) {
    const RasterGradients g = single_view_gradient(before, data.train[size_t(t.view_order[size_t(b)])], c);
    for (size_t k = 0; k < expected.size(); ++k) expected[k] += g.means[k];
  }
  // From zero moments one step leaves m = (1 − β1^B)·g: the summed gradient it was given.
  const double decay = 1.0 - double(batch_adam_settings(AdamSettings{}, batch).beta1);
  const std::vector<float>& m = t.gaussians().adam_m[int(ParamGroup::Means)];
  double largest = 0;
  for (const double e : expected) largest = std::max(largest, std::abs(e));
  ASSERT_GT(largest, 0.0);
  for (size_t k = 0; k < expected.size(); ++k)
    // Float sums of 4 terms and one float product: a few ulp of the largest gradient.
    ASSERT_NEAR(double(m[k]) / decay, expected[k], 1e-5 * largest) << "mean gradient " << k;
}

// The view tree's adds, worked out by hand: views [5, 2, 7, 0] split into the even {2, 0} and
// the odd {5, 7}; the evens into 0 (bit 1 clear) and 2, the odds into 5 and 7.
TEST(Batch, TheViewTreeAddsEvensThenOddsBitByBit) {
  std::vector<std::pair<int, int>> adds;
  const auto log = [&](int into, int from) { adds.emplace_back(into, from); };
  const std::vector<int> views = {5, 2, 7, 0};
  EXPECT_EQ(sum_in_view_tree(views, log), 3);
  EXPECT_EQ(adds, (std::vector<std::pair<int, int>>{{3, 1}, {0, 2}, {3, 0}}));
  // One view drawn twice (an epoch boundary in the batch): its entries in draw order.
  adds.clear();
  const std::vector<int> twice = {4, 1, 4};
  EXPECT_EQ(sum_in_view_tree(twice, log), 0);
  EXPECT_EQ(adds, (std::vector<std::pair<int, int>>{{0, 2}, {0, 1}}));
  adds.clear();
  EXPECT_EQ(sum_in_view_tree(std::vector<int>{6}, log), 0);
  EXPECT_TRUE(adds.empty());
  EXPECT_EQ(sum_in_view_tree({}, log), -1);
}

// The property ranks rely on (docs/METHOD.md §6, ranks): one process's view-tree sum of a batch
// equals, bit for bit, each rank's view-tree sum of its own views (view ≡ r mod N, zero when it
// holds none) added in the communicator's rank tree, written out here for N = 2 and 4. The
// values are chosen so that the order of float additions changes the result; summing in draw
// order instead must break the equality for some batch (the check can fail).
TEST(Batch, OneProcessAndPowerOfTwoRanksAddTheSameFloatsInTheSameOrder) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> view_of(0, 15), length_of(1, 8);
  std::uniform_real_distribution<float> small(0.5f, 8.0f);
  const auto tree_of = [](std::span<const int> views, std::vector<float> x) {
    const int root = sum_in_view_tree(views, [&](int into, int from) { x[size_t(into)] += x[size_t(from)]; });
    return root < 0 ? 0.0f : x[size_t(root)];
  };
  const auto own_share = [](const std::vector<int>& views, const std::vector<float>& x, int r, int n) {
    std::pair<std::vector<int>, std::vector<float>> mine;
    for (size_t k = 0; k < views.size(); ++k)
      if (views[k] % n == r) mine.first.push_back(views[k]), mine.second.push_back(x[k]);
    return mine;
  };
  int draw_order_differs = 0;
  for (int trial = 0; trial < 500; ++trial) {
    std::vector<int> views(size_t(length_of(rng)));
    std::vector<float> x(views.size());
    for (size_t k = 0; k < views.size(); ++k) {
      views[k] = view_of(rng);
      x[k] = k == 0 ? 1e8f : small(rng);  // 1e8 + a few loses them unless they were added first
    }
    const float one = tree_of(views, x);
    for (const int n : {2, 4}) {
      std::vector<float> part(static_cast<size_t>(n));
      for (int r = 0; r < n; ++r) {
        const auto [v, xs] = own_share(views, x, r, n);
        part[size_t(r)] = tree_of(v, xs);
      }
      const float ranks = n == 2 ? part[0] + part[1] : (part[0] + part[2]) + (part[1] + part[3]);
      ASSERT_EQ(std::bit_cast<uint32_t>(one), std::bit_cast<uint32_t>(ranks))
          << "trial " << trial << ", " << n << " ranks";
    }
    float drawn = 0.0f;
    for (const float v : x) drawn += v;
    draw_order_differs += std::bit_cast<uint32_t>(drawn) != std::bit_cast<uint32_t>(one);
  }
  EXPECT_GT(draw_order_differs, 0);
}

TEST(Batch, AdamStepWithBatchBetasAndRootRateMatchesDouble) {
  const int views = 4;
  GaussianSet set;
  set.sh_degree = 0;
  set.resize(2);
  for (size_t i = 0; i < set.means.size(); ++i) set.means[i] = 0.1f * float(i) - 0.2f;
  TrainableGaussians t(set);
  RasterGradients grads;
  grads.means = {0.5f, -0.25f, 1e-3f, 2.0f, -3.0f, 0.125f};
  grads.log_scales.assign(6, 0.0f), grads.quats.assign(8, 0.0f), grads.opacity_logits.assign(2, 0.0f);
  grads.colors.assign(6, 0.0f);
  const LearningRates lr = batch_learning_rates(LearningRates{}, views);
  const double rate = 1.6e-4 * 2.0;  // lr.means × √4
  const double b1 = std::pow(0.9, views), b2 = std::pow(0.999, views);
  std::vector<double> p(set.means.begin(), set.means.end()), m(6, 0.0), v(6, 0.0);
  for (int step = 1; step <= 3; ++step) {
    t.adam_update(grads, lr, AdamSettings{}, -1, {}, views);
    const double bc1 = 1 - std::pow(0.9, views * step), bc2 = 1 - std::pow(0.999, views * step);
    for (size_t k = 0; k < 6; ++k) {
      const double g = grads.means[k];
      m[k] = b1 * m[k] + (1 - b1) * g;
      v[k] = b2 * v[k] + (1 - b2) * g * g;
      p[k] -= rate / bc1 * m[k] / (std::sqrt(v[k]) / std::sqrt(bc2) + 1e-15);
    }
    EXPECT_EQ(t.adam_step, int64_t(views) * step);  // the bias correction counts views
    for (size_t k = 0; k < 6; ++k)
      // The update is about rate (3.2e-4) per step; float arithmetic keeps it to ~1e-6 of that
      // and of the parameter (|p| ≤ 0.3).
      ASSERT_NEAR(double(t.params.means[k]), p[k], 1e-7) << "step " << step << " value " << k;
    for (size_t k = 0; k < 6; ++k) grads.means[k] *= -0.5f;  // another gradient next step
  }
  // One view: the rates and betas are today's.
  const LearningRates one = batch_learning_rates(LearningRates{}, 1);
  EXPECT_EQ(one.means, LearningRates{}.means);
  EXPECT_EQ(batch_adam_settings(AdamSettings{}, 1).beta2, AdamSettings{}.beta2);
}

// The view indices in [first, first + views) at which the trainer's schedules fire.
bool holds(int64_t first, int views, int64_t t) { return t >= first && t < first + views; }

TEST(Batch, DensityControlFiresAtTheSameViewsSeenAtAnyBatch) {
  const TrainingData data = synthetic_training_data(8, 64, 48, 3);
  // The schedule's events, from its definition (density.hpp, distractors.hpp) at batch 1.
  TrainConfig base = short_schedule(420);
  base.distractors.initial_count = 40;
  base.distractors.reference_pixels = 0;
  base.densify.reset_alpha_every = 3;  // an opacity reset every 150 views, at 150·k + 50
  const int views_per_epoch = int(data.train.size());
  std::vector<int64_t> refine, reset, distractor_refine;
  for (int64_t t = 0; t < base.iterations; ++t) {
    if (t <= base.densify.warmup || t % base.densify.refine_every != 0) continue;
    refine.push_back(t);
    if (t < base.densify.stop_split_at && t % 150 == 50) reset.push_back(t);
    if (t % (int64_t(base.distractors.refine_every_epochs) * views_per_epoch) < base.densify.refine_every)
      distractor_refine.push_back(t);
  }
  ASSERT_FALSE(reset.empty());
  ASSERT_FALSE(distractor_refine.empty());
  for (const int batch : {1, 2, 3}) {
    TrainConfig c = base;
    c.batch = batch;
    Trainer t(data, c);
    std::vector<int64_t> got_refine, got_reset, got_distractor;
    while (t.current_step() < c.iterations) {
      const StepStats s = t.step();
      // Each event is reported by the step whose views hold it …
      for (const int64_t e : refine)
        if (holds(s.step, s.views, e) && s.refine.ran) got_refine.push_back(e);
      for (const int64_t e : reset)
        if (holds(s.step, s.views, e) && s.refine.opacity_reset) got_reset.push_back(e);
      for (const int64_t e : distractor_refine)
        if (holds(s.step, s.views, e) && s.distractor_refine.ran) got_distractor.push_back(e);
      // … and a step that holds none reports none.
      const bool any = std::any_of(refine.begin(), refine.end(), [&](int64_t e) { return holds(s.step, s.views, e); });
      if (!any) EXPECT_FALSE(s.refine.ran || s.distractor_refine.ran) << "batch " << batch << " step " << s.step;
    }
    EXPECT_EQ(got_refine, refine) << "batch " << batch;
    EXPECT_EQ(got_reset, reset) << "batch " << batch;
    EXPECT_EQ(got_distractor, distractor_refine) << "batch " << batch;
    EXPECT_EQ(t.current_step(), c.iterations);
  }
}

TEST(Batch, TheLastStepTakesTheViewsLeft) {
  const TrainingData data = synthetic_training_data(8, 40, 30, 3);
  Trainer t(data, static_batch_config(3, 7));
  std::vector<int> views;
  while (t.current_step() < 7) views.push_back(t.step().views);
  EXPECT_EQ(views, (std::vector<int>{3, 3, 1}));
  EXPECT_EQ(t.gaussians().adam_step, 7);
}

TEST(Batch, DistractorsAndEmbeddingsOfOnlyTheBatchsViewsChange) {
  const TrainingData data = synthetic_training_data(12, 64, 48, 3);
  TrainConfig c = short_schedule(50);
  c.batch = 3;
  c.distractors.initial_count = 40;
  c.distractors.reference_pixels = 0;
  c.appearance.enabled = true;
  Trainer t(data, c);
  const std::vector<TrainableGaussians> before = t.distractors();
  const std::vector<float> embeddings = t.appearance().image_embeddings;
  t.step();
  const std::set<int> batch{t.view_order[0], t.view_order[1], t.view_order[2]};
  ASSERT_EQ(batch.size(), 3u);  // one epoch's order: three different views
  const size_t dim = size_t(c.appearance.image_dim);
  EXPECT_EQ(t.appearance().adam_step, 3);  // the appearance model: one update per view
  for (size_t v = 0; v < data.train.size(); ++v) {
    const bool in_batch = batch.count(int(v)) > 0;
    const TrainableGaussians& d = t.distractors()[v];
    EXPECT_EQ(d.params.means != before[v].params.means, in_batch) << "view " << v;
    EXPECT_EQ(d.adam_step, in_batch ? 1 : 0) << "view " << v;  // one update of its own, unbatched
    const bool moved = !std::equal(embeddings.begin() + v * dim, embeddings.begin() + (v + 1) * dim,
                                   t.appearance().image_embeddings.begin() + v * dim);
    // The MLP's last layer starts at zero, so the batch's first view has no embedding gradient
    // yet; the second and third views see the MLP its update left.
    if (!in_batch)
      EXPECT_FALSE(moved) << "view " << v;
    else if (int(v) != t.view_order[0])
      EXPECT_TRUE(moved) << "view " << v;
  }
}

TEST(Batch, ABatchLargerThanTheRefinementPeriodIsRefused) {
  nlohmann::json j = {{"batch", 101}};
  try {
    config_from_json(j);
    FAIL() << "batch 101 with densify.refine_every 100 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("batch"), std::string::npos) << e.what();
  }
  EXPECT_THROW(config_from_json(nlohmann::json{{"batch", 0}}), std::invalid_argument);
  EXPECT_EQ(config_from_json(nlohmann::json{{"batch", 8}}).batch, 8);
  TrainConfig c = short_schedule(10);
  c.batch = 51;  // refine_every 50
  EXPECT_THROW(Trainer(synthetic_training_data(8, 64, 48, 3), c), std::invalid_argument);
}

}  // namespace
}  // namespace desplat::test
