// --effects auto's evidence (docs/METHOD.md §10, choosing the effects) on synthetic captures
// with known answers: each photo's gain from the SfM tracks, the open-sky cells of a photo, the
// background turned on for a sky and only then, the opaque term off for a steady sky, and how
// the effect names map to switches.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <set>

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

TrainingData synth_capture(const std::string& name, const std::string& extra) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("desplat_effects_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  testing::spit(dir / "scene.json",
                R"({"base": ")" + (std::filesystem::path(DESPLAT_SOURCE_DIR) / "data/synthetic/bench.json").string() +
                    R"(", "camera.width": 160, "camera.height": 120, "views.count": 24,
                                            "distractors.clutter_ratio": 0)" +
                    extra + "}");
  synth::GenerateOptions g;
  g.out = dir / "capture";
  synth::generate_scene(synth::load_description(dir / "scene.json"), g);
  TrainingData data = load_training_data(load_colmap_scene(g.out, SceneOptions{}));
  std::filesystem::remove_all(dir);
  return data;
}

// Known answer: each view's photo scaled by a known gain; --effects auto's estimate (the median
// ratio over the view's track samples) recovers it, and the spread decides. The synthetic
// capture with its own exposure changes (±1 stop, ±10 % white balance) turns appearance on;
// the same capture without them does not.
TEST(Effects, AutoReadsEachViewsGainFromTheTracksAndTurnsAppearanceOnlyOnWhenTheySpread) {
  const TrainingData clean = synth_capture("clean", "");
  const EffectsEvidence none = examine_effects(clean);
  ASSERT_EQ(none.judged_views, int(clean.train.size()));
  EXPECT_FALSE(none.appearance) << none.reason;

  TrainingData scaled = clean;
  const float stops[6] = {-0.6f, -0.3f, 0.0f, 0.2f, 0.4f, 0.7f};
  for (size_t v = 0; v < scaled.train.size(); ++v) {
    FloatImage photo = to_float(scaled.train[v].image);
    for (float& p : photo.pixels) p = std::min(1.0f, p * std::exp2(stops[v % 6]));
    scaled.train[v].image = to_bytes(photo);
  }
  const EffectsEvidence ev = examine_effects(scaled);
  EXPECT_TRUE(ev.appearance) << ev.reason;
  for (size_t v = 0; v < scaled.train.size(); ++v)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(ev.views[v].log2_gain[c] - none.views[v].log2_gain[c], stops[v % 6], 0.05)
          << "view " << v << " channel " << c;

  const TrainingData exposed = synth_capture("exposed", R"(, "exposure": {"stops": 1, "white_balance": 0.1})");
  const EffectsEvidence real = examine_effects(exposed);
  EXPECT_TRUE(real.appearance) << real.reason;

  // Without tracks there is no evidence: nothing is turned on, and the reason says so.
  TrainingData no_tracks = clean;
  for (auto& views : no_tracks.point_train_views) views.clear();
  const EffectsEvidence blind = examine_effects(no_tracks);
  EXPECT_FALSE(blind.appearance);
  EXPECT_CONTAINS(blind.reason, "too few to judge");
}

// The open-sky test (open_sky.hpp) on a hand-drawn 64 × 64 photo, 8 × 8 cells of 8 pixels: a
// smooth sky above y = 24 and a 4-pixel checkerboard below, every ground cell holding an SfM
// sample except three kinds: cell (5, 3), textured (SfM failed to match it: not sky); a smooth
// 3 × 3-cell patch at columns 2–4, rows 4–6 enclosed by ground (not connected to the top edge:
// not sky); and one sky cell (6, 1) that holds a sample (something SfM saw up there). The
// answer, by construction: the 24 sky cells but (6, 1) are open, nothing else.
TEST(OpenSky, CellsOfAHandDrawnPhoto) {
  const int n = 64;
  const Camera camera = look_at_camera(0.2f, 1.0f, n, n);
  ByteImage photo{n, n, 3, std::vector<uint8_t>(size_t(n) * n * 3)};
  auto in_patch = [](int cx, int cy) { return cx >= 2 && cx <= 4 && cy >= 4 && cy <= 6; };
  std::vector<long long> samples;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const bool sky = y < 24, smooth = sky || in_patch(x / 8, y / 8);
      const uint8_t v = smooth ? uint8_t(110 + y / 2) : (((x / 4 + y / 4) % 2) ? 204 : 51);
      for (int c = 0; c < 3; ++c) photo.pixels[3 * (size_t(y) * n + x) + c] = v;
    }
  for (int cy = 0; cy < 8; ++cy)
    for (int cx = 0; cx < 8; ++cx) {
      const bool sampled = (cy >= 3 && !in_patch(cx, cy) && !(cx == 5 && cy == 3)) || (cx == 6 && cy == 1);
      if (sampled) samples.push_back((long long)(cy * 8 + 3) * n + cx * 8 + 5);
    }
  const OpenSkyCells sky = open_sky_cells(camera, photo, samples, 8, 0.25f);
  ASSERT_EQ(sky.cell, 8);
  ASSERT_EQ(sky.columns, 8);
  ASSERT_EQ(sky.rows, 8);
  for (int cy = 0; cy < 8; ++cy)
    for (int cx = 0; cx < 8; ++cx)
      EXPECT_EQ(sky.open[size_t(cy) * 8 + cx], cy < 3 && !(cx == 6 && cy == 1)) << "cell " << cx << ", " << cy;
  EXPECT_DOUBLE_EQ(sky.share(n, n), 23.0 * 64 / (n * n));
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([&] { open_sky_cells(camera, photo, samples, 0, 0.25f); }),
                  "columns must be ≥ 1");
}

// Known answer: the generator knows where it drew a sky. The bench capture looks down on its
// ground plane (no sky in any frame); the same world seen from low cameras shows a sky above
// the horizon in every frame, which auto reads as an open, smooth region with no SfM point
// connected to the top edge. Painting a texture over that region (a surface SfM failed to
// match, not a sky) turns the background off again.
TEST(Effects, AutoTurnsTheBackgroundModelOnForASkyAndOnlyThen) {
  const TrainingData ground = synth_capture("ground", "");
  const EffectsEvidence no_sky = examine_effects(ground);
  EXPECT_FALSE(no_sky.background) << no_sky.background_reason;
  EXPECT_LT(no_sky.open_top_share, 0.02);

  const std::string low = R"(, "sky.enabled": true, "views.height": 1.0, "views.target": [0, 0, 0.5])";
  const TrainingData sky = synth_capture("sky", low);
  const EffectsEvidence with_sky = examine_effects(sky);
  EXPECT_TRUE(with_sky.background) << with_sky.background_reason;
  EXPECT_GT(with_sky.open_top_share, 0.2);
  EXPECT_CONTAINS(with_sky.background_reason, "open sky above the scene");

  TrainingData painted = sky;
  for (TrainView& v : painted.train)
    for (int y = 0; y < v.image.height / 2; ++y)
      for (int x = 0; x < v.image.width; ++x)
        for (int c = 0; c < 3; ++c)
          v.image.pixels[3 * (size_t(y) * v.image.width + x) + c] = ((x / 6 + y / 6) % 2) ? 204 : 51;
  const EffectsEvidence textured = examine_effects(painted);
  EXPECT_FALSE(textured.background) << textured.background_reason;
  std::vector<std::string> why;
  EXPECT_EQ(choose_effects({false, false, false}, with_sky, why).to_string(), "background");
  ASSERT_EQ(why.size(), 2u);  // appearance, background (distractors are the probe's)
  EXPECT_CONTAINS(why[1], "background on: in the median training view");
}

// The background's opaque term is off for a steady sky (BackgroundSettings::
// opaque_off_for_steady_sky), by the same evidence as auto: the low-camera capture with a sky
// and one exposure drops it; the same capture with per-photo exposure, the capture without a
// sky, the sky capture without tracks, and the rule switched off keep it. Then a Trainer on the
// steady sky trains bit for bit as one told λ_o = 0, and not as one with the term.
TEST(Effects, TheOpaqueTermIsOffForASteadySkyOnly) {
  const std::string low = R"(, "sky.enabled": true, "views.height": 1.0, "views.target": [0, 0, 0.5])";
  const TrainingData sky = synth_capture("steady_sky", low);
  const TrainingData exposed =
      synth_capture("exposed_sky", low + R"(, "exposure": {"stops": 1, "white_balance": 0.1})");
  const TrainingData ground = synth_capture("steady_ground", "");
  TrainingData blind = sky;
  for (auto& views : blind.point_train_views) views.clear();
  TrainConfig c;
  c.distractors.enabled = false;
  c.background.enabled = true;
  EXPECT_EQ(effective_config(c, sky).background.lambda_opaque, 0.0f);
  EXPECT_EQ(effective_config(c, exposed).background.lambda_opaque, 0.01f);
  EXPECT_EQ(effective_config(c, ground).background.lambda_opaque, 0.01f);
  EXPECT_EQ(effective_config(c, blind).background.lambda_opaque, 0.01f);
  TrainConfig kept = c;
  kept.background.opaque_off_for_steady_sky = false;
  EXPECT_EQ(effective_config(kept, sky).background.lambda_opaque, 0.01f);

  c.iterations = 40;
  c.num_downscales = 0;
  c.background.hidden_width = 16;
  kept.iterations = 40;
  kept.num_downscales = 0;
  kept.background.hidden_width = 16;
  TrainConfig zero = kept;
  zero.background.lambda_opaque = 0.0f;
  Trainer a(sky, c), b(sky, zero), live(sky, kept);
  EXPECT_EQ(a.config().background.lambda_opaque, 0.0f);
  for (int i = 0; i < 40; ++i) a.step(), b.step(), live.step();
  EXPECT_EQ(a.gaussians().params.opacity_logits, b.gaussians().params.opacity_logits);
  EXPECT_EQ(a.background().mlp, b.background().mlp);
  EXPECT_NE(a.gaussians().params.opacity_logits, live.gaussians().params.opacity_logits);
}

// Auto adds appearance to the configured set when the evidence calls for it and never turns
// off what the preset or --config turned on.
TEST(Effects, AutoOnlyAddsAppearanceToTheConfiguredSet) {
  EffectsEvidence calls, quiet;
  calls.appearance = true, calls.reason = "spread";
  quiet.reason = "flat";
  std::vector<std::string> why;
  // Distractors stay as configured (the transient probe decides them afterwards).
  EXPECT_EQ(choose_effects({true, false}, calls, why).to_string(), "distractors,appearance");
  ASSERT_EQ(why.size(), 2u);
  EXPECT_CONTAINS(why[0], "appearance on: spread");
  EXPECT_CONTAINS(why[1], "background off");
  why.clear();
  EXPECT_EQ(choose_effects({false, false}, quiet, why).to_string(), "none");
  why.clear();
  EXPECT_EQ(choose_effects({true, true}, quiet, why).to_string(), "distractors,appearance");
  ASSERT_EQ(why.size(), 2u);
  EXPECT_CONTAINS(why[0], "on because --config turns it on");
}

TEST(Effects, NamesMapToSwitchesAndUnknownOnesAreRefused) {
  TrainConfig c;
  Effects::parse("appearance,distractors").apply(c);
  EXPECT_TRUE(c.distractors.enabled);
  EXPECT_TRUE(c.appearance.enabled);
  EXPECT_EQ(Effects::of(c).to_string(), "distractors,appearance");
  Effects::parse("none").apply(c);
  EXPECT_FALSE(c.distractors.enabled || c.appearance.enabled);
  EXPECT_EQ(Effects::of(c).to_string(), "none");
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] { Effects::parse("distractors,sky"); }),
                  "unknown effect 'sky'");
  Effects::parse("background,distractors").apply(c);
  EXPECT_TRUE(c.background.enabled && c.distractors.enabled && !c.appearance.enabled);
  EXPECT_EQ(Effects::of(c).to_string(), "distractors,background");
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] { Effects::parse("auto,appearance"); }),
                  "'auto' stands alone");
  EXPECT_CONTAINS(testing::error_of<std::invalid_argument>([] { Effects::parse(""); }), "--effects is empty");
}

}  // namespace
}  // namespace desplat::test
