// Per-image appearance (docs/METHOD.md §10; the paper's appendix, after WildGaussians): each
// training image j has an embedding e_j, each static Gaussian i an embedding z_i (its row of
// GaussianSet::features), and an MLP maps (z_i, the SH DC coefficient c̄_i, e_j) to an affine
// colour change (β, γ) ∈ R³ × R³. Gaussian i is blended with c̃_i = max(γ ⊙ c_i + β, 0), c_i
// its view-dependent colour after SH; γ = 1 + o_γ, β = o_β for the MLP's outputs o, and the
// last layer starts at zero, so a new model renders its plain colours.
//
// The MLP runs only on the Gaussians visible in the view (between rasterize_project and
// rasterize_blend), in a fixed partition of those rows into slabs: outputs and gradients are
// bit-identical for any thread count. Hidden activations are recomputed in the backward pass
// rather than kept (memory stays O(slab) instead of O(visible · width · layers)).
//
// Units: colours in [0, 1]-ish linear RGB like the rasterizer's; embeddings are unitless.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "desplat/core/gaussians.hpp"
#include "desplat/raster/raster.hpp"

namespace desplat {

struct AppearanceSettings {
  bool enabled = false;
  int image_dim = 32;           // e_j
  int fourier_frequencies = 4;  // z_i has 6 per frequency: sin and cos of each axis
  // 32, not the paper's 128: as good on per-image exposure and white balance at a fraction of
  // the cost (docs/METHOD.md §10); --preset paper sets 128.
  int hidden_width = 32;
  int hidden_layers = 2;
  float lr_mlp = 5e-4f;  // z_i's rate is LearningRates::features
  // e_j's rate: the test-time fit's (test_lr). An image embedding learns only on its own view's
  // steps, one in V; at the paper's 1e-3 (--preset paper) the trained looks have not settled
  // (their spread grows in proportion to the rate) and the MLP grows steep in e, and the
  // 128-step fit below falls short of where a long fit gets. At 1e-2 it does not
  // (docs/METHOD.md §10).
  float lr_image = 1e-2f;
  // Test-time appearance (the Photo Tourism protocol): a held-out view's embedding is fitted
  // for this many Adam steps at this rate on the left half of the image, everything else frozen.
  int test_steps = 128;
  float test_lr = 0.01f;
  // Where that fit starts. On (the default): from the training photo's look that best fits the
  // left half — each training view's embeddings scored by the photometric loss on a small
  // downscaled copy of the test view, one forward render each (a look is a colour change over
  // the whole frame, so a small copy ranks the looks as the full view does) — so a photo far
  // from the average look does not spend its 128 steps getting there. Off (--preset paper):
  // from the mean training look (docs/METHOD.md §10).
  bool test_start_from_best_look = true;

  int feature_dim() const { return 6 * fourier_frequencies; }
  // Throws std::invalid_argument naming the setting (prefix "appearance.").
  void validate() const;
};

// WildGaussians' initialization of z_i: the positions [N, 3] are centred on their mean and
// scaled per axis by the 97th percentile of |x| to about [0, 1]; then for each axis and
// frequency k < `frequencies`: sin(2π·2^k·x), cos(2π·2^k·x). Returns [N, 6·frequencies],
// axis-major (axis 0's 2·frequencies values first).
std::vector<float> fourier_features(std::span<const float> means, int frequencies);

// The MLP's weights, the image embeddings and their Adam state. Layer l's weight matrix is
// stored row-major [out_l, in_l] followed by its bias [out_l]; the first layer's input is
// (z, c̄, e) in that order.
struct AppearanceModel {
  AppearanceSettings settings;
  std::vector<float> mlp;                             // all layers, flat
  std::vector<float> image_embeddings;                // [views, image_dim]
  std::vector<float> mlp_m, mlp_v, embed_m, embed_v;  // Adam moments, same shapes
  int64_t adam_step = 0;

  AppearanceModel() = default;
  // Hidden layers PyTorch-style U(±1/√in), the last layer zero, embeddings N(0, 0.01²).
  AppearanceModel(const AppearanceSettings& settings, size_t views, uint64_t seed);
  size_t views() const { return settings.image_dim > 0 ? image_embeddings.size() / size_t(settings.image_dim) : 0; }
  std::span<const float> embedding(size_t view) const {
    return std::span<const float>(image_embeddings).subspan(view * settings.image_dim, settings.image_dim);
  }
  // The MLP's layer sizes: input, hidden…, 6.
  std::vector<int> layer_sizes() const;
  size_t mlp_floats() const;
  // One Adam step (the same formulation as the Gaussians') on the MLP and every embedding.
  // A gradient with a non-finite value changes nothing and returns false.
  bool adam_update(std::span<const float> d_mlp, std::span<const float> d_embeddings);
  // Throws std::logic_error when array sizes disagree with the settings.
  void check_consistent() const;
};

// One render's appearance pass: what forward keeps for backward, and the gradient buffers.
// Scratch reused between steps; owned by the caller.
struct AppearancePass {
  std::vector<int32_t> rows;     // the visible Gaussians, in index order
  std::vector<float> sh_rgb;     // [rows, 3] c before the change
  std::vector<uint8_t> active;   // [rows, 3] 1 where γ ⊙ c + β > 0 (the clamp passed it)
  std::vector<float> rgb_scale;  // [N, 3] ∂c̃/∂c: γ, or 0 where the clamp at 0 was active
  // backward's results
  std::vector<float> d_mlp;        // same shape as AppearanceModel::mlp
  std::vector<float> d_embedding;  // [image_dim] ∂L/∂e

  // Replaces fw.rgb of every visible Gaussian by c̃ under `embedding` (e, [image_dim]).
  // `gaussians` must be the set fw was projected from (SH colours, features of feature_dim).
  void forward(const AppearanceModel& model, std::span<const float> embedding, const GaussianSet& gaussians,
               RasterOutput& fw, int threads);
  // From grads.rgb (rasterize_backward with rgb_scale): fills d_mlp and d_embedding, writes
  // ∂L/∂z into grads.features and adds ∂L/∂c̄ through the MLP's input to the DC coefficients
  // in grads.colors. grads.features is resized to the set's shape (zero outside `rows`, and
  // on rows whose colour reached no pixel, which the MLP's backward skips).
  void backward(const AppearanceModel& model, std::span<const float> embedding, const GaussianSet& gaussians,
                RasterGradients& grads, int threads);
};

}  // namespace desplat
