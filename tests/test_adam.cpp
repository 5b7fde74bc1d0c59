// The Adam update against PyTorch's formulation evaluated here in double, with the SH
// rates per band, the inactive bands left alone, and non-finite rows reported.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "desplat/train/trainable.hpp"

namespace desplat::test {
namespace {

struct Reference {  // one float's Adam state, in double
  double p, m = 0, v = 0;
};

// PyTorch Adam (no weight decay, no amsgrad): m̂ = m/(1−β1ᵗ), v̂ = v/(1−β2ᵗ), p −= lr·m̂/(√v̂ + ε).
void reference_step(Reference& r, double g, double lr, int t, const AdamSettings& a) {
  r.m = a.beta1 * r.m + (1 - a.beta1) * g;
  r.v = a.beta2 * r.v + (1 - a.beta2) * g * g;
  const double m_hat = r.m / (1 - std::pow(double(a.beta1), t)), v_hat = r.v / (1 - std::pow(double(a.beta2), t));
  r.p -= lr * m_hat / (std::sqrt(v_hat) + a.eps);
}

GaussianSet random_set(std::mt19937& rng, size_t n, int sh_degree) {
  GaussianSet g;
  g.color_mode = ColorMode::SphericalHarmonics;
  g.sh_degree = sh_degree;
  g.resize(n);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  for (int k = 0; k < kParamGroups; ++k)
    for (float& x : g.*kParamGroupTable[k].values) x = normal(rng);
  return g;
}

RasterGradients random_grads(std::mt19937& rng, const GaussianSet& g) {
  RasterGradients grads;
  std::normal_distribution<float> normal(0.0f, 0.01f);
  for (int k = 0; k < kParamGroups; ++k) {
    std::vector<float>& dst = grads.*kParamGroupTable[k].grads;
    dst.resize((g.*kParamGroupTable[k].values).size());
    for (float& x : dst) x = normal(rng);
  }
  return grads;
}

TEST(Adam, MatchesPyTorchPerGroupAndSkipsInactiveBands) {
  std::mt19937 rng(5);
  const size_t n = 1300;                        // several of the update's row blocks
  TrainableGaussians t(random_set(rng, n, 1));  // 12 colour floats: DC + 3 band-1 coefficients
  const GaussianSet start = t.params;
  LearningRates lr;
  lr.means = 1e-3f;  // distinct rates, so a value updated at another group's rate shows
  std::array<std::vector<Reference>, kParamGroups> ref;
  for (int k = 0; k < kParamGroups; ++k)
    for (float x : t.param(ParamGroup(k))) ref[k].push_back({double(x)});
  const AdamSettings a;
  for (int step = 1; step <= 4; ++step) {
    const RasterGradients grads = random_grads(rng, t.params);
    const int trained = step <= 2 ? 3 : -1;  // degree 0 for two steps, then band 1 joins
    t.adam_update(grads, lr, a, trained);
    EXPECT_TRUE(t.nonfinite_groups.empty());
    for (int k = 0; k < kParamGroups; ++k) {
      const ParamGroupInfo& info = kParamGroupTable[k];
      const int width = t.floats_per_gaussian(info.id);
      const std::vector<float>& g = grads.*info.grads;
      for (size_t j = 0; j < ref[k].size(); ++j) {
        const int column = int(j % width);
        const bool colour_rest = info.id == ParamGroup::Colors && column >= 3;
        if (colour_rest && step <= 2) continue;  // inactive: Adam must not touch it
        // Band 1 starts its own moments at step 3 but shares the step count (bias correction).
        reference_step(ref[k][j], g[j], colour_rest ? lr.colors_rest : lr.*info.rate, step, a);
      }
      for (size_t j = 0; j < ref[k].size(); ++j) {
        const double rate = (info.id == ParamGroup::Colors && int(j % width) >= 3) ? lr.colors_rest : lr.*info.rate;
        // Each update moves a value by about its rate; float rounding of the value itself
        // (|p| ≲ 4, ulp 5e-7) dominates the error.
        ASSERT_NEAR(t.param(info.id)[j], ref[k][j].p, 2e-6 + 1e-3 * rate)
            << info.name << " value " << j << " step " << step;
      }
    }
    if (step <= 2)
      for (size_t i = 0; i < n; ++i)
        for (int c = 3; c < 12; ++c) {
          ASSERT_EQ(t.params.colors[12 * i + c], start.colors[12 * i + c]);
          ASSERT_EQ(t.adam_m[int(ParamGroup::Colors)][12 * i + c], 0.0f);
        }
  }
}

// Degree 3 with two bands trained (27 of 48 colour floats): every trained float follows
// PyTorch's Adam at its band's rate, the third band's 21 floats and moments stay as they were.
TEST(Adam, TrainsOnlyTheActiveBandsOfADegree3Colour) {
  std::mt19937 rng(11);
  const size_t n = 700;
  TrainableGaussians t(random_set(rng, n, 3));
  const GaussianSet start = t.params;
  LearningRates lr;
  lr.colors_dc = 2e-3f, lr.colors_rest = 1e-4f;
  const AdamSettings a;
  const RasterGradients grads = random_grads(rng, t.params);
  t.adam_update(grads, lr, a, 27);
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 48; ++c) {
      const size_t j = 48 * i + size_t(c);
      if (c >= 27) {
        ASSERT_EQ(t.params.colors[j], start.colors[j]) << "row " << i << " float " << c;
        ASSERT_EQ(t.adam_v[int(ParamGroup::Colors)][j], 0.0f) << "row " << i << " float " << c;
        continue;
      }
      Reference r{double(start.colors[j])};
      const double rate = c < 3 ? lr.colors_dc : lr.colors_rest;
      reference_step(r, grads.colors[j], rate, 1, a);
      ASSERT_NEAR(t.params.colors[j], r.p, 2e-6 + 1e-3 * rate) << "row " << i << " float " << c;
    }
}

// Selective Adam: a row not selected keeps its values and both moments bit for bit; a
// selected row follows PyTorch's Adam with the global step count (bias correction), so a
// row skipped for a while resumes with the step count the others reached.
TEST(Adam, SelectiveUpdateLeavesUnselectedRowsAndUsesTheGlobalStepCount) {
  std::mt19937 rng(7);
  const size_t n = 1300;  // runs of selected rows cross the update's 512-row blocks
  TrainableGaussians t(random_set(rng, n, 0));
  LearningRates lr;
  std::array<std::vector<Reference>, kParamGroups> ref;
  for (int k = 0; k < kParamGroups; ++k)
    for (float x : t.param(ParamGroup(k))) ref[k].push_back({double(x)});
  const AdamSettings a;
  std::bernoulli_distribution coin(0.6);
  for (int step = 1; step <= 5; ++step) {
    std::vector<uint8_t> rows(n);
    for (size_t i = 0; i < n; ++i) rows[i] = uint8_t(coin(rng));
    for (size_t i = 505; i < 530; ++i) rows[i] = 1;  // a run across a block boundary
    const TrainableGaussians before = t;
    const RasterGradients grads = random_grads(rng, t.params);
    t.adam_update(grads, lr, a, -1, rows);
    for (int k = 0; k < kParamGroups; ++k) {
      const ParamGroupInfo& info = kParamGroupTable[k];
      const size_t width = size_t(t.floats_per_gaussian(info.id));
      const std::vector<float>& g = grads.*info.grads;
      for (size_t j = 0; j < ref[k].size(); ++j) {
        const size_t row = j / width;
        if (!rows[row]) {
          ASSERT_EQ(t.param(info.id)[j], before.param(info.id)[j]) << info.name << " row " << row;
          ASSERT_EQ(t.adam_m[k][j], before.adam_m[k][j]);
          ASSERT_EQ(t.adam_v[k][j], before.adam_v[k][j]);
          continue;
        }
        reference_step(ref[k][j], g[j], lr.*info.rate, step, a);
        ASSERT_NEAR(t.param(info.id)[j], ref[k][j].p, 2e-6 + 1e-3 * lr.*info.rate)
            << info.name << " value " << j << " step " << step;
      }
    }
  }
  EXPECT_EQ(t.adam_step, 5);
}

// Every row selected is the plain update, bit for bit; a selection of the wrong length is an error.
TEST(Adam, SelectingEveryRowEqualsTheDenseUpdate) {
  std::mt19937 rng(8);
  TrainableGaussians dense(random_set(rng, 700, 1)), selective = dense;
  const RasterGradients grads = random_grads(rng, dense.params);
  dense.adam_update(grads, LearningRates{}, AdamSettings{}, 3);
  selective.adam_update(grads, LearningRates{}, AdamSettings{}, 3, std::vector<uint8_t>(700, 1));
  for (int k = 0; k < kParamGroups; ++k) {
    EXPECT_EQ(dense.param(ParamGroup(k)), selective.param(ParamGroup(k))) << kParamGroupTable[k].name;
    EXPECT_EQ(dense.adam_m[k], selective.adam_m[k]);
    EXPECT_EQ(dense.adam_v[k], selective.adam_v[k]);
  }
  EXPECT_THROW(selective.adam_update(grads, LearningRates{}, AdamSettings{}, 3, std::vector<uint8_t>(699, 1)),
               std::logic_error);
}

TEST(Adam, ReportsTheRowsAndGroupsThatWentNonFinite) {
  std::mt19937 rng(6);
  TrainableGaussians t(random_set(rng, 1100, 0));
  RasterGradients grads = random_grads(rng, t.params);
  grads.quats[4 * 700 + 2] = INFINITY;                    // row 700, quats
  grads.opacity_logits[3] = NAN;                          // row 3, opacity
  t.adam_v[int(ParamGroup::Means)][3 * 1099] = INFINITY;  // row 1099, a moment
  t.adam_update(grads, LearningRates{}, AdamSettings{});
  ASSERT_EQ(t.nonfinite_groups.size(), 1100u);
  for (size_t i = 0; i < 1100; ++i) {
    uint8_t want = 0;
    if (i == 700) want = 1u << int(ParamGroup::Quats);
    if (i == 3) want = 1u << int(ParamGroup::OpacityLogits);
    if (i == 1099) want = 1u << int(ParamGroup::Means);
    ASSERT_EQ(t.nonfinite_groups[i], want) << "row " << i;
  }
  // A clean step clears the report.
  t.keep(std::vector<uint8_t>(1100, 1));
  for (int k = 0; k < kParamGroups; ++k)
    for (size_t j = 0; j < t.param(ParamGroup(k)).size(); ++j)
      if (!std::isfinite(t.param(ParamGroup(k))[j]) || !std::isfinite(t.adam_m[k][j]) || !std::isfinite(t.adam_v[k][j]))
        t.param(ParamGroup(k))[j] = 0, t.adam_m[k][j] = 0, t.adam_v[k][j] = 0;
  t.adam_update(random_grads(rng, t.params), LearningRates{}, AdamSettings{});
  EXPECT_TRUE(t.nonfinite_groups.empty());
}

}  // namespace
}  // namespace desplat::test
