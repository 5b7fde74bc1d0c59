// The background model (docs/METHOD.md §11; the paper's appendix, after Splatfacto-W): what a
// photo shows where no Gaussian is — sky, a far wall — as a colour per ray direction that can
// change from photo to photo. Training image j has an embedding e_j; an MLP maps e_j to the
// coefficients of real spherical harmonics of degree ≤ 4 (core/spherical_harmonics.hpp), and
// the background of pixel p is
//
//   bg(p) = 0.5 + Σ_k c_k · Y_k(d_p),   d_p the unit ray direction of p's centre, world frame,
//
// composited behind both layers (raster/composite.hpp). Bands switch on one per
// sh_degree_interval steps. The MLP's last layer starts at zero, so a new model is a uniform
// mid-grey. The MLP runs once per rendered image (not per pixel): its cost is the per-pixel
// harmonics, ~25 multiply-adds per channel.
//
// The embeddings are the background model's own (not the appearance model's): each effect can
// be on alone, and each is one parameter group with its own Adam state.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "desplat/core/camera.hpp"
#include "desplat/raster/composite.hpp"

namespace desplat {

struct BackgroundSettings {
  bool enabled = false;
  int image_dim = 32;      // e_j
  int hidden_width = 128;  // the appendix: 3 hidden layers of 128
  int hidden_layers = 3;
  int sh_degree = 4;
  int sh_degree_interval = 500;  // one band more every this many steps (half the static layer's)
  // Adam rates (the authors'): the hidden layers and the band-0 outputs; bands ≥ 1 at 1/20 of
  // that, so the sky's mean colour settles before its variation with direction.
  float lr_mlp = 2e-3f, lr_rest = 1e-4f;
  // Our own embeddings' rate (unused while shared, below): the appearance embeddings' (1e-2,
  // AppearanceSettings::lr_image gives the reason), so that an own copy trains as the shared one
  // does; the authors' 1e-3 with --preset paper.
  float lr_image = 1e-2f;
  // L_bg (background_alpha_loss): λ_bg, and which pixels the background already explains.
  float lambda_alpha = 0.15f;
  // … and λ_o, the weight that keeps the layers opaque where it does not (a learned background
  // seen through a half-transparent static layer fits a photo as well as an opaque layer does).
  float lambda_opaque = 0.01f;
  // … except for a steady sky (effective_config sets λ_o to 0): photos of one exposure and
  // colour balance that show open sky, by --effects auto's evidence (effects.hpp). There the
  // term only makes the static layer paint the sky the background would draw. Where photos
  // differ in colour, the term is needed: without it a half-transparent static layer over a
  // per-photo background fakes the change; with no sky it is needed too (docs/METHOD.md §11).
  bool opaque_off_for_steady_sky = true;
  float explained_error = 0.003f;  // mean |photo − bg| over RGB below this …
  float explained_share = 0.6f;    // … in more than this share of the pixel's 3×3 box
  // With appearance on too, read the appearance model's embedding e_j instead of our own (the
  // authors' form): a photo's exposure is then one vector for the scene and the sky alike, and
  // the Photo Tourism protocol fits one embedding per test view, not two. Our own embeddings
  // stay in the model (and the checkpoint) unused. Needs image_dim = appearance.image_dim.
  bool share_appearance_embedding = true;

  int sh_degree_at(int64_t step) const;
  // Throws std::invalid_argument naming the setting (prefix "background.").
  void validate() const;
};

// The MLP's weights, the image embeddings and their Adam state. Layer l is stored row-major
// [out_l, in_l] followed by its bias [out_l]; the outputs are the coefficients [25, 3]
// (coefficient-major: output 3k + c is coefficient k of channel c).
struct BackgroundModel {
  BackgroundSettings settings;
  std::vector<float> mlp;
  std::vector<float> image_embeddings;  // [views, image_dim]
  std::vector<float> mlp_m, mlp_v, embed_m, embed_v;
  int64_t adam_step = 0;

  BackgroundModel() = default;
  // Hidden layers U(±1/√in), the last layer zero, embeddings N(0, 0.01²).
  BackgroundModel(const BackgroundSettings& settings, size_t views, uint64_t seed);
  size_t views() const { return settings.image_dim > 0 ? image_embeddings.size() / size_t(settings.image_dim) : 0; }
  std::span<const float> embedding(size_t view) const {
    return std::span<const float>(image_embeddings).subspan(view * settings.image_dim, settings.image_dim);
  }
  // The mean of the training embeddings: the background of a photo nobody has seen.
  std::vector<float> mean_embedding() const;
  std::vector<int> layer_sizes() const;  // image_dim, hidden…, 75
  size_t mlp_floats() const;
  // One Adam step; a non-finite gradient changes nothing and returns false.
  bool adam_update(std::span<const float> d_mlp, std::span<const float> d_embeddings);
  // Throws std::logic_error when array sizes disagree with the settings.
  void check_consistent() const;
};

// One image's background: forward keeps what backward needs. Scratch owned by the caller.
struct BackgroundPass {
  std::vector<float> activations;   // every layer's output (hidden after ReLU), in order
  std::vector<float> coefficients;  // [25·3] the MLP's output
  int degree = 0;
  std::vector<float> image;               // [P·3] bg(p)
  std::vector<float> d_image;             // [P·3] ∂L/∂bg, filled by the caller (composite backward)
  std::vector<float> d_mlp, d_embedding;  // backward's results

  // Fills `image` for `camera` (P = width·height) with bands 0 … degree.
  void forward(const BackgroundModel& model, std::span<const float> embedding, const Camera& camera, int degree,
               int threads);
  // From d_image: d_mlp and d_embedding. Bit-identical for any thread count.
  void backward(const BackgroundModel& model, std::span<const float> embedding, const Camera& camera, int threads);
  Background background() const { return Background(std::span<const float>(image)); }
};

// L_bg (the appendix, after Splatfacto-W): where the background already explains the photo —
// mean |target − bg| over RGB < explained_error, and that holds in more than explained_share
// of the pixel's 3×3 box (pixels outside the image count as not explained) — the layers
// should be transparent: λ_bg · mean over those pixels B of A = A_d + (1 − A_d)·A_s, with A_d
// held fixed (the distractors answer to their own regularizer). Everywhere else (kept pixels
// not in B) they should be opaque: + λ_o · mean over those of (1 − A) — the static opacity
// regularizer λ_s of docs/METHOD.md §4, which a learned background replaces, restricted to
// where no sky is. Returns the value and ADDS its gradient to d_static_alpha. `distractor`
// may be empty; `keep` ([P], optional): ignored pixels are in neither set. Sizes: [P·3]
// images, [P] alphas.
double background_alpha_loss(std::span<const float> background, std::span<const float> target, Layer statics,
                             Layer distractor, int width, int height, const BackgroundSettings& settings,
                             std::span<float> d_static_alpha, std::span<const float> keep = {});

// The unit ray direction through the centre of pixel (x, y), world frame.
std::array<float, 3> pixel_ray_direction(const Camera& camera, int x, int y);

}  // namespace desplat
