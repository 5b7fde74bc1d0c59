// DeSplat training on the CPU (docs/METHOD.md §4–7): static Gaussians shared by all views
// plus, per training view, distractor Gaussians only that view renders; with
// config.distractors.enabled = false it is the static Splatfacto baseline.
//
// All geometry is in the normalized world frame (§1). Training images are float RGB
// [H, W, 3] at the full training resolution; the resolution schedule derives the
// lower-resolution copies (block averages) once per view and keeps them.
// Not thread-safe: one Trainer per thread; it uses OpenMP internally.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "desplat/comm/communicator.hpp"
#include "desplat/core/camera.hpp"
#include "desplat/core/image.hpp"
#include "desplat/core/stopwatch.hpp"
#include "desplat/core/world_frame.hpp"
#include "desplat/raster/composite.hpp"
#include "desplat/raster/raster.hpp"
#include "desplat/train/appearance.hpp"
#include "desplat/train/background.hpp"
#include "desplat/train/density.hpp"
#include "desplat/train/distractors.hpp"
#include "desplat/train/train_config.hpp"
#include "desplat/train/trainable.hpp"
#include "desplat/train/training_data.hpp"
#include "desplat/train/transient_points.hpp"

namespace desplat {

// Seconds. forward/backward/optimizer are the static branch; `distractor` is all the
// work of the view's distractor branch (its forward, backward, Adam and refinement);
// `loss` includes the compositing and its gradient.
// `appearance` is the appearance model's forward, backward and Adam (docs/METHOD.md §10),
// `background` the background model's (§11).
struct StepTimings {
  double forward = 0, backward = 0, loss = 0, optimizer = 0, distractor = 0, appearance = 0, background = 0;
  double total() const { return forward + backward + loss + optimizer + distractor + appearance + background; }
};

// The timing blocks of one step, in one place: each block's wall time goes to one field of
// StepTimings (what metrics.json reports).
class StepProfiler {
 public:
  template <class Fn>
  void time(double StepTimings::*block, Fn&& fn) {
    const Stopwatch watch;
    fn();
    timings.*block += watch.seconds();
  }
  StepTimings timings;
};

// One layer's share of a step (the static layer, or the view's distractor layer): its render,
// the gradient of the loss with respect to that render, and the resulting parameter gradients.
// Scratch reused every step; owned by the Trainer.
// With an appearance model (the static layer, docs/METHOD.md §10) the colours change under
// `embedding` between projection and blending, and backward also leaves the model's gradients
// in appearance.d_mlp / d_embedding; appearance_seconds is the time that took (forward and
// backward since the last render).
struct LayerPass {
  RasterOutput forward;
  std::vector<float> d_color, d_alpha;  // [P·3], [P] ∂L/∂(premultiplied colour, alpha)
  RasterGradients grads;
  AppearancePass appearance;
  double appearance_seconds = 0;

  void render(const TrainableGaussians& g, const Camera& camera, const RasterSettings& rs,
              const AppearanceModel* model = nullptr, std::span<const float> embedding = {}) {
    appearance_seconds = 0;
    if (!model) return rasterize_forward(g.params.view(), camera, rs, forward);
    rasterize_project(g.params.view(), camera, rs, forward);
    const Stopwatch watch;
    appearance.forward(*model, embedding, g.params, forward, rs.num_threads);
    appearance_seconds += watch.seconds();
    rasterize_blend(camera, rs, forward);
  }
  Layer layer() const { return {forward.color, forward.alpha}; }
  void backward(const TrainableGaussians& g, const Camera& camera, const RasterSettings& rs,
                const AppearanceModel* model = nullptr, std::span<const float> embedding = {}) {
    rasterize_backward(g.params.view(), camera, rs, forward, d_color, d_alpha, {}, grads,
                       model ? std::span<const float>(appearance.rgb_scale) : std::span<const float>());
    if (!model) return;
    const Stopwatch watch;
    appearance.backward(*model, embedding, g.params, grads, rs.num_threads);
    appearance_seconds += watch.seconds();
  }
};

// One view's distractor refinement, for the history in metrics.json.
struct ViewRefinement {
  int view = 0;  // index into data.train
  int64_t before = 0, after = 0, budget = kUnlimitedGrowth;
  int64_t idle = 0;  // culled first by the idle cull (cull_idle_distractors)
  // The buffer's summed alpha before growth (distractor_alpha_sum, full training resolution
  // [px]); computed only under distractors.max_alpha_sum, else 0.
  double alpha_sum = 0;
  RefineReport report;
};

// One optimizer step: a batch of `views` training views, the view indices
// [step, step + views). Loss and PSNR are the views' means; counts are summed over them.
struct StepStats {
  int64_t step = 0;
  int views = 1;
  double loss = 0, psnr = 0;
  size_t gaussians = 0;         // static
  size_t view_distractors = 0;  // distractors of this step's views
  RefineReport refine;
  RefineReport distractor_refine;                      // summed over views when they were refined this step
  std::vector<ViewRefinement> distractor_refinements;  // per view, when they were refined
  int64_t reseeded = 0;                                // distractors seeded in this step's views (starved or uncovered)
  int64_t nonfinite_pruned = 0;
  StepTimings timings;
  // Work of the static layer's render: Gaussian–pixel pairs whose α was evaluated, and
  // Gaussians visible in the view (the optimizer updates all `gaussians`).
  int64_t static_pairs = 0;
  size_t static_visible = 0;
  // This rank's collectives in the step (CommTotals; zero in one process). Their time is
  // also inside the timing blocks that called them.
  int64_t comm_bytes = 0;
  double comm_seconds = 0;
};

// How a test view was scored.
enum class EvalProtocol {
  full_image,         // the render (plain colours) against the whole photo
  appearance_halves,  // Photo Tourism: the view's embeddings fitted on the left half, scored on the right
};
const char* to_string(EvalProtocol p);

// A photo's look under the per-image models: its appearance embedding ([image_dim] of the
// appearance model) and its background embedding (of the background model); either empty
// when that model is off or not asked for.
struct ViewLook {
  std::vector<float> appearance, background;
  // fit_look: the training view whose look the fit started from, or "mean" (the mean look).
  std::string start;
};

struct ViewMetrics {
  std::string name;
  double psnr = 0, ssim = 0;
  EvalProtocol protocol = EvalProtocol::full_image;
  // The same render scored on the right half only, whatever the protocol: the number that
  // compares a model with per-image embeddings to one without (equal to psnr/ssim under
  // appearance_halves).
  double psnr_right_half = 0, ssim_right_half = 0;
  ViewLook look;  // appearance_halves: the fitted embeddings (render the view in its look)
};

// The configuration a Trainer built from `config` trains with (what config.json records):
// without distractors the model is the Splatfacto baseline and starts from every sparse
// point, so the transient-point action is keep; the background's opaque term is off for a
// steady sky in `data` (BackgroundSettings::opaque_off_for_steady_sky).
TrainConfig effective_config(TrainConfig config, const TrainingData& data);

class Trainer {
 public:
  // `data` and `comm` must outlive the trainer. With a communicator of more than one rank the
  // trainer is one rank of a data-parallel job (docs/METHOD.md §6, ranks): `data` holds the
  // photos of this rank's views only (rank_of_view; the others' images empty), every rank
  // holds the same static Gaussians and random state and takes the same steps, and a view's
  // distractors live on its rank. Every rank must call step(), evaluate(), gather_to_root()
  // and keep_own_share() alike (they are collectives). Null or one rank: one process.
  Trainer(const TrainingData& data, TrainConfig config, Communicator* comm = nullptr);

  // One optimizer step over min(batch, iterations − current_step()) views (the batch when
  // the run is already at its length).
  StepStats step();
  // Views seen so far: the index of the next view to train.
  int64_t current_step() const { return step_; }
  const TrainConfig& config() const { return config_; }
  const TrainingData& data() const { return data_; }
  const TrainableGaussians& gaussians() const { return gaussians_; }
  TrainableGaussians& mutable_gaussians() { return gaussians_; }  // tests and checkpoints
  // Per training view (data.train order); empty when distractors are disabled.
  const std::vector<TrainableGaussians>& distractors() const { return distractors_; }
  std::vector<TrainableGaussians>& mutable_distractors() { return distractors_; }
  size_t distractor_count() const;  // over all views
  std::mt19937_64& rng() { return rng_; }
  const std::mt19937_64& rng() const { return rng_; }
  Communicator* communicator() const { return comm_; }  // null in one process
  int rank() const { return rank_; }
  int ranks() const { return ranks_; }
  // Whether this rank holds training view `view`'s photo, distractors and growth state.
  bool owns_view(size_t view) const { return rank_of_view(view, ranks_) == rank_; }
  // Collective, before a checkpoint or the outputs: rank 0 (every rank, in fact) receives every
  // view's distractors and growth state and the static statistics' totals, so the state it
  // holds is the whole job's. keep_own_share() returns to training's division of the state.
  void gather_to_root();
  // Each rank keeps only its own views' distractors, and ranks other than 0 hold no static
  // statistics (the job's totals are the sum over ranks). After a restore or a gather.
  void keep_own_share();

  // Renders a view with the static Gaussians ([H, W, 3], clamped): in look.appearance's
  // appearance when given (else the plain colours), over look.background's learned background
  // when given (else over the colour `background`).
  FloatImage render(const Camera& camera, const std::array<float, 3>& background, const ViewLook& look = {}) const;
  // Every layer of training view `train_view` at its full training resolution.
  ViewLayers render_layers(size_t train_view, const std::array<float, 3>& background) const;
  // What every render at this step uses: the configured threads and the active SH degree.
  RasterSettings raster_settings() const;
  // PSNR/SSIM of every view's render: the whole image over the evaluation background for a
  // model without per-image models; with appearance or background the Photo Tourism protocol
  // (fit_look on the left half, score the right half).
  std::vector<ViewMetrics> evaluate(const std::vector<TrainView>& views) const;
  // Test-time appearance: the embeddings of every per-image model this one has, for `view`,
  // fitted together by appearance.test_steps Adam steps at appearance.test_lr on the pixels
  // where `fit` is 1 ([H·W], the view's own mask applies too), starting from the training look
  // that fits those pixels best (appearance.test_start_from_best_look, best_training_look) or
  // from the mean of the training embeddings; everything else frozen.
  ViewLook fit_look(const TrainView& view, std::span<const float> fit) const;
  // Training view j's own look (its embeddings), and the mean of them all.
  ViewLook training_look(size_t j) const;
  ViewLook mean_look() const;
  // The training view whose look gives the lowest photometric loss on the pixels of `view`
  // where `fit` is 1, judged on a copy at most kLookSearchPixels across (the look is a colour
  // change over the whole frame: a small copy ranks the looks as the full one does, at a
  // fraction of the cost of one render per training view).
  size_t best_training_look(const TrainView& view, std::span<const float> fit) const;
  bool has_per_image_models() const { return config_.appearance.enabled || config_.background.enabled; }
  // Appearance model (appearance.hpp); empty (no views) when config.appearance is off.
  const AppearanceModel& appearance() const { return appearance_; }
  AppearanceModel& mutable_appearance() { return appearance_; }
  // Background model (background.hpp); empty (no views) when config.background is off.
  const BackgroundModel& background() const { return background_; }
  BackgroundModel& mutable_background() { return background_; }

  // Where non-finite values are reported (once per incident); default: stderr.
  std::function<void(const std::string&)> warn;

  // Exposed for checkpointing: the epoch permutation and the position in it.
  std::vector<int32_t> view_order;
  int64_t view_order_pos = 0;
  // Per training view, from its latest step (docs/METHOD.md §7, growth control): the fractions of pixels the
  // static layer (as distractors.count_connected_misses counts them) and the composite leave
  // unexplained, and whether its latest refinement
  // found it starved or uncovered (seeded at its next step).
  std::vector<float> view_static_unexplained, view_composite_unexplained;
  std::vector<int32_t> view_seed_due;
  // Sparse points judged transient at initialization, and the distractors seeded from them
  // (transient_points.hpp; 0 when the action is keep).
  int64_t transient_point_count = 0, transient_seeded = 0;
  // The camera path whose free space the static refinements keep clear (free_space.hpp), and
  // how many static Gaussians it culled in this process (not kept across a resume).
  const CameraPath& camera_path() const { return camera_path_; }
  int64_t camera_path_culled = 0;            // by either rule of train/free_space.hpp, this run
  int64_t camera_path_blind_gap_culled = 0;  // of those, by the blind-gap rule
  void set_step(int64_t s) { step_ = s; }
  // The latest step's last view's pixels neither layer explains [H·W of its camera]; after a
  // step that seeded that view, the eroded mask they were drawn from. For inspection.
  const std::vector<uint8_t>& uncovered_mask() const;
  // Whether the background reads the appearance embedding (BackgroundSettings::
  // share_appearance_embedding with both models on), and the embedding it reads for a view.
  bool shared_embedding() const;
  std::span<const float> sky_embedding(size_t view) const;

 private:
  const TrainingData& data_;
  TrainConfig config_;
  Communicator* comm_ = nullptr;  // null: one process
  int rank_ = 0, ranks_ = 1;
  TrainableGaussians gaussians_;
  CameraPath camera_path_;  // from the training cameras and sparse points, at construction
  double scene_depth_ = 0;  // median_scene_depth of the same [world units]; 0: no points
  std::vector<TrainableGaussians> distractors_;
  AppearanceModel appearance_;
  BackgroundModel background_;
  std::vector<float> d_embeddings_;  // [views, image_dim] scratch: the step view's row is nonzero
  std::mt19937_64 rng_;
  int64_t step_ = 0;
  // Per view: images at factor 2, 4, … (index k holds factor 2^(k+1)), built when the
  // resolution schedule first needs them and freed once it has reached full resolution.
  std::vector<std::vector<ByteImage>> downscaled_;
  FloatImage target_;  // the latest view's photo in float, at its resolution
  // Per view with a mask: the mask at factor 2, 4, … (a pixel is kept when all it covers is),
  // freed with downscaled_.
  std::vector<std::vector<std::vector<uint8_t>>> downscaled_keep_;
  std::vector<float> keep_;  // the latest view's mask in float (the losses weigh pixels with it)
  // One view of the step's batch, kept from its pass until the step's seeding.
  struct BatchView {
    int view = 0;                    // index into data.train
    int64_t index = 0;               // views seen before it (the schedules' step)
    int factor = 1;                  // its resolution factor
    Camera camera;                   // at that factor
    std::vector<uint8_t> uncovered;  // its pixels neither layer explains [H·W of camera]
    RasterGradients grads;           // its static gradient, on its rank, until the batch's sum
  };
  // Scratch reused every step.
  std::vector<BatchView> batch_views_;
  LayerPass static_pass_, distractor_pass_;
  BackgroundPass background_pass_;
  std::vector<float> composite_, d_composite_;
  RasterGradients batch_grads_;         // the batch's summed static gradients
  std::vector<uint8_t> batch_visible_;  // [N] visible in any of the batch's views (selective Adam)
  std::vector<float> packed_;           // ranks: the batch's gradients and flags in one array

  int next_view();
  // One view's pass (docs/METHOD.md §4–7): draws the view and its background, renders, takes
  // the loss and the backward, applies its per-view updates (distractors, appearance,
  // background), keeps its static gradient in bv.grads for the batch's sum and adds its
  // statistics to the static buffer's (`first`: the first view of the batch on this rank,
  // which starts the visible flags).
  // Every rank draws the view and its random background; only the view's rank trains it.
  // Returns whether this rank trained it.
  bool train_view(BatchView& bv, bool first, StepProfiler& profile, StepStats& stats);
  // The static buffer's one Adam step over the batch's `views` views and its refinement when
  // the refinement schedule falls in the batch; returns the refinement's view index, or −1.
  int64_t update_static(int views, StepProfiler& profile, StepStats& stats);
  RasterSettings raster_settings_at(int64_t index) const;
  // The static means' rate at view index `index`: lr.means decaying exponentially to
  // means_lr_final over means_lr_decay_steps views.
  float means_lr_at(int64_t index) const;
  // The view's photo at 1/factor resolution, converted into target_ (valid until the next call).
  const FloatImage& target_at(int view, int factor);
  // The view's mask at 1/factor resolution, converted into keep_ (valid until the next call);
  // empty when the view has no mask.
  std::span<const float> keep_at(int view, int factor);
  std::span<const uint8_t> adam_rows(const RasterOutput& forward) const;
  // `what` names the set in warnings, e.g. "static Gaussian" or "distractor of view " + name
  // (built only when something is pruned).
  // `index`: the view index the warning names.
  int64_t prune_nonfinite(TrainableGaussians& g, int64_t index, const std::function<std::string()>& what);
  // Every view's distractor refinement at view index `index` (its schedule's event).
  void refine_all_distractors(int64_t index, int image_size, int factor, StepStats& stats);
  // Culls the static Gaussians on camera_path_ after a static refinement; counts them in `report`.
  void cull_camera_path(RefineReport& report);
  // Seeds the batch view's training view when its latest refinement found it starved or
  // uncovered and this pass's residual agrees (docs/METHOD.md §7, growth control). Returns
  // the count added.
  int64_t seed_if_due(BatchView& bv);
  // seeding_allowed at view index `index`, over one distractor-refinement period.
  bool seeding_settled(int64_t index) const;
  // TransientPointAction::seed: distractors where the transient points project in the
  // training views that observe them.
  void seed_from_transient_points(const std::vector<uint8_t>& transient);
  void seed_view_from_transient_points(size_t view, const std::vector<uint8_t>& transient);
  // The ranks' parts of the batch into every rank's batch_grads_ and batch_visible_ (a rank
  // without a view in the batch adds zeros), and the step's summed statistics.
  void sum_batch_over_ranks(StepStats& stats);
  // The static statistics' totals on every rank (sums; the screen radius's maximum), before
  // a refinement decides on them.
  void reduce_static_statistics();
  // Every rank's copy of the random state becomes rank `root`'s: after `root` drew from it
  // for a view only it holds, the ranks draw on in step.
  void follow_random_state(int root);
  // Per-view values only their owner sets: every rank receives the owners' values.
  void share_view_values();
};

// Whether step `step` trains at the same resolution as step − period (clamped at 0): the
// distractor seeding rules wait one distractor-refinement period after a resolution switch,
// because the residual right after it is the static layer's missing detail at the new
// resolution, not a transient object (docs/METHOD.md §7, growth control).
bool resolution_settled(const TrainConfig& config, int64_t step, int64_t period);

// Whether the distractor seeding rules may run at `step`: resolution_settled, from
// distractors.seed_after on, and (with distractors.seed_waits_after_reset) no static opacity
// reset in the last `period` steps (docs/METHOD.md §7, growth control).
bool seeding_allowed(const TrainConfig& config, int64_t step, int64_t period);

// What the densification statistics count as seen this step (docs/METHOD.md §7): a visible
// Gaussian whose projected centre lies on an ignored pixel (keep = 0; its gradient from there
// is zero) or where `hiding_alpha` > kDistractorMaskThreshold (the view's distractor layer
// covers it; densify.hide_behind_distractors) is marked not visible in `fw`, so the view does
// not dilute its mean gradient. `keep` and `hiding_alpha` are [H·W] of fw's image, or empty.
void hide_unseen_centers(RasterOutput& fw, std::span<const float> keep, std::span<const float> hiding_alpha);

// The factor densify.gradient_per_seen_pixel puts on a static step's gradient statistic: the
// kept pixels over the pixels the static layer is seen on, Σ k / Σ k·(1 − A_d), with k the
// keep weights (empty: every pixel kept) and A_d the view's distractor alpha, both [H·W] of
// the step's image. 1 without distractors (empty alpha) or where no kept pixel is seen at all.
float seen_pixel_gradient_scale(std::span<const float> keep, std::span<const float> distractor_alpha);

// The camera of an image at 1/factor resolution (sizes rounded down, as downscale_bytes).
Camera downscale_camera(const Camera& c, int factor);
// Trainer::best_training_look judges the looks on a copy of the view halved until its longer
// side is at most this many pixels.
inline constexpr int kLookSearchPixels = 160;
// A user mask ([height·width], 1 = keep) at 1/factor resolution, sized as downscale_camera: a
// coarse pixel is kept only when every pixel it covers is.
std::vector<uint8_t> downscale_keep(const std::vector<uint8_t>& keep, int width, int height, int factor);

}  // namespace desplat
