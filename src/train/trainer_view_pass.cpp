// One training view's pass within a step (docs/METHOD.md §4–7): the static and the view's
// distractor layer are rendered separately and composited over a random background (or the
// background model's); photometric loss plus the opacity regularizers; backward through the
// composite into both; the view's own updates (distractors, appearance, background); its
// static gradient and statistics join the batch's.
#include "desplat/train/trainer.hpp"

#include <algorithm>
#include <cmath>

#include "desplat/train/batch.hpp"
#include "desplat/train/loss.hpp"
#include "desplat/train/mask_coherence.hpp"
#include "desplat/train/view_residual.hpp"

namespace desplat {

bool Trainer::train_view(BatchView& bv, bool first, StepProfiler& profile, StepStats& stats) {
  const int64_t t = bv.index;
  const int view = next_view();
  std::array<float, 3> bg_color = config_.eval_background;
  if (config_.random_background && !config_.background.enabled) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    bg_color = {u(rng_), u(rng_), u(rng_)};
  }
  const int factor = config_.downscale_at(t);
  if (factor == 1) {  // the schedule never goes back to a coarser level: give the pyramid's memory back
    for (std::vector<ByteImage>& levels : downscaled_)
      if (!levels.empty()) std::vector<ByteImage>().swap(levels);
    std::vector<std::vector<std::vector<uint8_t>>>().swap(downscaled_keep_);
  }
  bv.view = view, bv.factor = factor;
  bv.camera = downscale_camera(data_.train[view].camera, factor);
  if (!owns_view(size_t(view))) {
    // Its rank records the view's statistics; the first view after a reset marks them begun
    // on every rank (accumulate_statistics' first-view rule applies once, on that view's rank).
    if (t < config_.densify.stop_split_at) gaussians_.statistics_empty = false;
    bv.uncovered.clear();
    return false;
  }
  const Camera& cam = bv.camera;
  const FloatImage& target = target_at(view, factor);
  const std::span<const float> keep = keep_at(view, factor);
  const size_t pixels = size_t(cam.width) * cam.height;
  const RasterSettings rs = raster_settings_at(t);
  // A view whose distractors were all culled has no second pass at all.
  TrainableGaussians* distractors = nullptr;
  if (config_.distractors.enabled && distractors_[view].size() > 0) distractors = &distractors_[view];
  stats.view_distractors += distractors ? distractors->size() : 0;
  const AppearanceModel* look = config_.appearance.enabled ? &appearance_ : nullptr;
  const std::span<const float> embedding = look ? appearance_.embedding(size_t(view)) : std::span<const float>();

  // 1. Render each layer, and the background behind them.
  const bool learned_bg = config_.background.enabled;
  if (learned_bg)
    profile.time(&StepTimings::background, [&] {
      background_pass_.forward(background_, sky_embedding(size_t(view)), cam, config_.background.sh_degree_at(t),
                               config_.threads);
    });
  const Background bg = learned_bg ? background_pass_.background() : Background(bg_color);
  profile.time(&StepTimings::forward, [&] { static_pass_.render(gaussians_, cam, rs, look, embedding); });
  const double appearance_forward = static_pass_.appearance_seconds;
  stats.static_pairs += static_pass_.forward.evaluated_pairs;
  stats.static_visible +=
      size_t(std::count(static_pass_.forward.visible.begin(), static_pass_.forward.visible.end(), 1));
  if (distractors) profile.time(&StepTimings::distractor, [&] { distractor_pass_.render(*distractors, cam, rs); });

  // 2. Composite, loss, and the loss's gradient with respect to each layer (docs/METHOD.md §4).
  profile.time(&StepTimings::loss, [&] {
    const Layer statics = static_pass_.layer();
    const Layer distractor = distractors ? distractor_pass_.layer() : Layer{};
    composite_.resize(3 * pixels);
    composite_layers(statics, distractor, bg, composite_);
    d_composite_.resize(3 * pixels);
    const PhotometricLoss loss =
        photometric_loss(composite_, target.pixels, cam.width, cam.height, config_.ssim_lambda, d_composite_, keep);
    static_pass_.d_color.resize(3 * pixels);
    static_pass_.d_alpha.resize(pixels);
    distractor_pass_.d_color.resize(distractors ? 3 * pixels : 0);
    distractor_pass_.d_alpha.resize(distractors ? pixels : 0);
    background_pass_.d_image.resize(learned_bg ? 3 * pixels : 0);
    composite_layers_backward(statics, distractor, bg, d_composite_,
                              {static_pass_.d_color, static_pass_.d_alpha, distractor_pass_.d_color,
                               distractor_pass_.d_alpha, background_pass_.d_image});
    double view_loss = loss.loss;
    // With a learned background the static layer need not be opaque everywhere (the sky is
    // the background's): L_bg replaces λ_s (docs/METHOD.md §11).
    if (config_.distractors.enabled && config_.distractors.regularize)
      view_loss += alpha_regularizers(statics, distractor, learned_bg ? 0.0f : config_.distractors.lambda_static,
                                      config_.distractors.lambda_distractor, static_pass_.d_alpha,
                                      distractor_pass_.d_alpha, keep);
    if (learned_bg)
      view_loss += background_alpha_loss(background_pass_.image, target.pixels, statics, distractor, cam.width,
                                         cam.height, config_.background, static_pass_.d_alpha, keep);
    if (distractors && config_.distractors.regularize && config_.distractors.lambda_mask_tv > 0)
      view_loss += mask_total_variation(distractor.alpha, cam.width, cam.height, config_.distractors.lambda_mask_tv,
                                        distractor_pass_.d_alpha, keep);
    // Like the owned-pixel pull, only once the static layer has had its chance (owned_after).
    if (distractors && config_.distractors.regularize && config_.distractors.lambda_occluder_colour > 0 &&
        t >= config_.distractors.owned_after)
      view_loss += occluder_colour_prior(distractor, target.pixels, config_.distractors.lambda_occluder_colour,
                                         distractor_pass_.d_color, distractor_pass_.d_alpha, keep);
    if (config_.distractors.enabled) {
      const DistractorSettings& ds = config_.distractors;
      const ViewResidual residual = measure_view_residual(
          statics, distractor, composite_, target.pixels, bg, cam.width,
          ResidualPenalties{ds.explained_tolerance, ds.lambda_explained, t >= ds.owned_after ? ds.lambda_owned : 0.0f,
                            ds.count_connected_misses},
          distractor_pass_.d_alpha, ds.reseed_starved_views || ds.seed_uncovered ? &bv.uncovered : nullptr, keep);
      view_loss += residual.penalty;
      // What the growth rules count as the static layer's misses (DistractorSettings).
      view_static_unexplained[view] =
          float(ds.count_connected_misses ? residual.static_area_fraction() : residual.static_fraction());
      view_composite_unexplained[view] = float(residual.composite_fraction());
    }
    stats.loss += view_loss;
    stats.psnr += psnr(composite_, target.pixels, keep);
  });

  // 3. Backward through each layer's rasterization, and the view's own models' updates.
  profile.time(&StepTimings::backward, [&] { static_pass_.backward(gaussians_, cam, rs, look, embedding); });
  // The appearance model's share of the static passes is reported on its own.
  profile.timings.forward -= appearance_forward;
  profile.timings.backward -= static_pass_.appearance_seconds - appearance_forward;
  profile.timings.appearance += static_pass_.appearance_seconds;
  const bool shared = shared_embedding();
  if (learned_bg)
    profile.time(&StepTimings::background, [&] {
      background_pass_.backward(background_, sky_embedding(size_t(view)), cam, config_.threads);
      const size_t dim = size_t(config_.background.image_dim);
      d_embeddings_.assign(background_.image_embeddings.size(), 0.0f);
      if (!shared) std::copy_n(background_pass_.d_embedding.begin(), dim, d_embeddings_.begin() + size_t(view) * dim);
      if (!background_.adam_update(background_pass_.d_mlp, d_embeddings_))
        warn("step " + std::to_string(t) + ": the background model's gradient is not finite; its update was skipped");
    });
  if (look)
    profile.time(&StepTimings::appearance, [&] {
      const size_t dim = size_t(config_.appearance.image_dim);
      d_embeddings_.assign(appearance_.image_embeddings.size(), 0.0f);
      std::copy_n(static_pass_.appearance.d_embedding.begin(), dim, d_embeddings_.begin() + size_t(view) * dim);
      if (shared)
        for (size_t k = 0; k < dim; ++k) d_embeddings_[size_t(view) * dim + k] += background_pass_.d_embedding[k];
      if (!appearance_.adam_update(static_pass_.appearance.d_mlp, d_embeddings_))
        warn("step " + std::to_string(t) + ": the appearance model's gradient is not finite; its update was skipped");
    });
  if (distractors) profile.time(&StepTimings::distractor, [&] { distractor_pass_.backward(*distractors, cam, rs); });

  // 4. The static statistics of this view, and its distractors' own Adam step.
  profile.time(&StepTimings::optimizer, [&] {
    // The rows selective Adam updates are the rasterizer's visible ones in any of the batch's
    // views, taken before the statistics hide those centred on ignored pixels (they still
    // have a gradient).
    if (config_.selective_adam) {
      const std::vector<uint8_t>& visible = static_pass_.forward.visible;
      if (first)
        batch_visible_.assign(visible.begin(), visible.end());
      else
        for (size_t i = 0; i < visible.size(); ++i) batch_visible_[i] |= visible[i];
    }
    // Behind this view's distractor mask a static Gaussian is not seen (hide_behind_distractors).
    const bool hide_behind = distractors && config_.densify.stats.hide_behind_distractors;
    hide_unseen_centers(static_pass_.forward, keep,
                        hide_behind ? distractor_pass_.forward.alpha : std::span<const float>());
    if (t < config_.densify.stop_split_at) {
      // Judged per pixel the static layer is seen on (gradient_per_seen_pixel).
      const float seen_scale = distractors && config_.densify.stats.gradient_per_seen_pixel
                                   ? seen_pixel_gradient_scale(keep, distractor_pass_.forward.alpha)
                                   : 1.0f;
      gaussians_.accumulate_statistics(static_pass_.forward, static_pass_.grads, config_.densify.stats, seen_scale);
    }
    // The view's static gradient waits for the batch's sum in the view tree (Trainer::step);
    // the backward's per-entry scratch stays with the pass, so the batch holds no copy of it.
    std::swap(bv.grads, static_pass_.grads);
    std::swap(bv.grads.entry_scratch, static_pass_.grads.entry_scratch);
  });
  // The view's distractor buffer (its statistics are kept after densification stops:
  // culling unseen distractors needs them).
  if (distractors)
    profile.time(&StepTimings::distractor, [&] {
      // The distractors' means follow the static means' decay, at this view's index.
      const double decay = double(means_lr_at(t)) / double(config_.lr.means);
      LearningRates dlr = config_.distractors.lr;
      dlr.means = float(dlr.means * decay);
      distractors->adam_update(distractor_pass_.grads, dlr, AdamSettings{}, -1, adam_rows(distractor_pass_.forward));
      hide_unseen_centers(distractor_pass_.forward, keep, {});
      distractors->accumulate_statistics(distractor_pass_.forward, distractor_pass_.grads, config_.densify.stats);
      stats.nonfinite_pruned +=
          prune_nonfinite(*distractors, t, [&] { return "distractor of view " + data_.train[view].name; });
    });
  return true;
}

}  // namespace desplat
