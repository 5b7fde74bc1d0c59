// The background model's forward and backward passes and L_bg (docs/METHOD.md §11).
#include "desplat/train/background.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "desplat/core/spherical_harmonics.hpp"
#include "desplat/train/embedding_mlp.hpp"
#include "desplat/train/trainable.hpp"

namespace desplat {
namespace {

constexpr int kCoefficients = sh_coefficients(kMaxShDegree);  // 25
constexpr int kOutputs = 3 * kCoefficients;
// Rows of pixels are summed in this many fixed slabs whatever the thread count: the
// coefficient gradient is bit-identical for any --threads.
constexpr int kSlabs = 16;

int team(int threads) { return threads > 0 ? threads : omp_get_max_threads(); }

}  // namespace

int BackgroundSettings::sh_degree_at(int64_t step) const {
  return int(std::min<int64_t>(step / std::max(1, sh_degree_interval), sh_degree));
}

void BackgroundSettings::validate() const {
  auto positive = [](int v, const char* name) {
    if (v <= 0)
      throw std::invalid_argument(std::string("background.") + name + " must be > 0 (got " + std::to_string(v) + ")");
  };
  positive(image_dim, "image_dim");
  positive(hidden_width, "hidden_width");
  positive(hidden_layers, "hidden_layers");
  positive(sh_degree_interval, "sh_degree_interval");
  if (sh_degree < 0 || sh_degree > kMaxShDegree)
    throw std::invalid_argument("background.sh_degree must be 0 … 4 (got " + std::to_string(sh_degree) + ")");
  // A rate of 0 freezes its group, as everywhere.
  for (auto [v, name] : {std::pair{lr_mlp, "lr_mlp"}, std::pair{lr_rest, "lr_rest"}, std::pair{lr_image, "lr_image"},
                         std::pair{lambda_alpha, "lambda_alpha"}, std::pair{lambda_opaque, "lambda_opaque"},
                         std::pair{explained_error, "explained_error"}})
    if (!(v >= 0 && std::isfinite(v)))
      throw std::invalid_argument(std::string("background.") + name + " must be ≥ 0 (got " + std::to_string(v) + ")");
  if (!(explained_share >= 0 && explained_share < 1))
    throw std::invalid_argument("background.explained_share must be in [0, 1) (got " + std::to_string(explained_share) +
                                ")");
}

std::vector<int> BackgroundModel::layer_sizes() const {
  std::vector<int> sizes{settings.image_dim};
  for (int l = 0; l < settings.hidden_layers; ++l) sizes.push_back(settings.hidden_width);
  sizes.push_back(kOutputs);
  return sizes;
}

size_t BackgroundModel::mlp_floats() const { return mlp_weight_count(layer_sizes()); }

BackgroundModel::BackgroundModel(const BackgroundSettings& s, size_t views, uint64_t seed) : settings(s) {
  settings.validate();
  std::mt19937_64 rng(seed);
  mlp = initial_mlp_weights(layer_sizes(), rng);
  image_embeddings = initial_embeddings(views * size_t(settings.image_dim), rng);
  mlp_m.assign(mlp.size(), 0.0f);
  mlp_v.assign(mlp.size(), 0.0f);
  embed_m.assign(image_embeddings.size(), 0.0f);
  embed_v.assign(image_embeddings.size(), 0.0f);
}

std::vector<float> BackgroundModel::mean_embedding() const {
  const size_t dim = size_t(settings.image_dim), n = views();
  std::vector<float> e(dim, 0.0f);
  for (size_t j = 0; j < n; ++j)
    for (size_t k = 0; k < dim; ++k) e[k] += embedding(j)[k] / float(n);
  return e;
}

void BackgroundModel::check_consistent() const { check_per_image_model(*this, "background"); }

bool BackgroundModel::adam_update(std::span<const float> d_mlp, std::span<const float> d_embeddings) {
  if (d_mlp.size() != mlp.size() || d_embeddings.size() != image_embeddings.size())
    throw std::logic_error("background adam_update: gradient sizes differ from the parameters");
  if (!all_finite(d_mlp) || !all_finite(d_embeddings)) return false;
  const AdamSettings a;
  const AdamBiasCorrection bc = advance_adam_step(adam_step, a);
  const double bc1 = bc.bc1;
  const float sqrt_bc2 = bc.sqrt_bc2;
  auto step = [&](size_t begin, size_t end, float lr) {
    adam_span(mlp.data() + begin, mlp_m.data() + begin, mlp_v.data() + begin, d_mlp.data() + begin, end - begin,
              float(lr / bc1), sqrt_bc2, a);
  };
  // The last layer's rows 0–2 and biases 0–2 are band 0 (lr_mlp); the rest are bands ≥ 1.
  const size_t hidden = size_t(settings.hidden_width);
  const size_t last_w = mlp.size() - size_t(kOutputs) * (hidden + 1), last_b = mlp.size() - kOutputs;
  step(0, last_w + 3 * hidden, settings.lr_mlp);
  step(last_w + 3 * hidden, last_b, settings.lr_rest);
  step(last_b, last_b + 3, settings.lr_mlp);
  step(last_b + 3, mlp.size(), settings.lr_rest);
  adam_span(image_embeddings.data(), embed_m.data(), embed_v.data(), d_embeddings.data(), image_embeddings.size(),
            float(settings.lr_image / bc1), sqrt_bc2, a);
  return true;
}

std::array<float, 3> pixel_ray_direction(const Camera& c, int x, int y) {
  const double dc[3] = {(x + 0.5 - c.cx) / c.fx, (y + 0.5 - c.cy) / c.fy, 1.0};
  double d[3];  // R_cwᵀ · d_cam
  for (int i = 0; i < 3; ++i) d[i] = c.R_cw[i] * dc[0] + c.R_cw[3 + i] * dc[1] + c.R_cw[6 + i] * dc[2];
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  return {float(d[0] / n), float(d[1] / n), float(d[2] / n)};
}

void BackgroundPass::forward(const BackgroundModel& model, std::span<const float> e, const Camera& camera, int deg,
                             int threads) {
  if (int(e.size()) != model.settings.image_dim)
    throw std::invalid_argument("background: the image embedding has " + std::to_string(e.size()) +
                                " values, the model expects " + std::to_string(model.settings.image_dim));
  model.check_consistent();
  degree = std::clamp(deg, 0, kMaxShDegree);
  // The MLP, once.
  const std::vector<int> sizes = model.layer_sizes();
  activations.clear();
  std::vector<float> in(e.begin(), e.end());
  const float* w = model.mlp.data();
  for (size_t l = 0; l + 1 < sizes.size(); ++l) {
    const int n_in = sizes[l], n_out = sizes[l + 1];
    const bool last = l + 2 == sizes.size();
    std::vector<float> out(n_out);
    for (int o = 0; o < n_out; ++o) {
      float s = w[size_t(n_out) * n_in + o];  // bias
      for (int i = 0; i < n_in; ++i) s += w[size_t(o) * n_in + i] * in[i];
      out[o] = last ? s : std::max(s, 0.0f);
    }
    activations.insert(activations.end(), out.begin(), out.end());
    w += size_t(n_out) * (n_in + 1);
    in = std::move(out);
  }
  coefficients = in;
  // The harmonics, per pixel.
  const int width = camera.width, height = camera.height, terms = sh_coefficients(degree);
  image.resize(size_t(width) * height * 3);
#pragma omp parallel for schedule(static) num_threads(team(threads))
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const std::array<float, 3> d = pixel_ray_direction(camera, x, y);
      float Y[kCoefficients];
      sh_basis<float, kMaxShDegree>(degree, d[0], d[1], d[2], Y);
      for (int c = 0; c < 3; ++c) {
        float v = 0.5f;
        for (int k = 0; k < terms; ++k) v += coefficients[3 * k + c] * Y[k];
        image[(size_t(y) * width + x) * 3 + c] = v;
      }
    }
}

void BackgroundPass::backward(const BackgroundModel& model, std::span<const float> e, const Camera& camera,
                              int threads) {
  const int width = camera.width, height = camera.height, terms = sh_coefficients(degree);
  if (d_image.size() != size_t(width) * height * 3 || image.size() != d_image.size())
    throw std::invalid_argument("background backward: the gradient image does not match the forward pass");
  // ∂L/∂c_k = Σ_p ∂L/∂bg(p) · Y_k(d_p), summed per slab of rows, then the slabs in order.
  std::vector<double> slab_sums(size_t(kSlabs) * kOutputs, 0.0);
#pragma omp parallel for schedule(static) num_threads(team(threads))
  for (int s = 0; s < kSlabs; ++s) {
    double* sum = slab_sums.data() + size_t(s) * kOutputs;
    for (int y = height * s / kSlabs; y < height * (s + 1) / kSlabs; ++y)
      for (int x = 0; x < width; ++x) {
        const std::array<float, 3> d = pixel_ray_direction(camera, x, y);
        float Y[kCoefficients];
        sh_basis<float, kMaxShDegree>(degree, d[0], d[1], d[2], Y);
        const float* g = d_image.data() + (size_t(y) * width + x) * 3;
        for (int k = 0; k < terms; ++k)
          for (int c = 0; c < 3; ++c) sum[3 * k + c] += double(g[c]) * Y[k];
      }
  }
  std::vector<float> d_out(kOutputs, 0.0f);
  for (int o = 0; o < kOutputs; ++o) {
    double total = 0;
    for (int s = 0; s < kSlabs; ++s) total += slab_sums[size_t(s) * kOutputs + o];
    d_out[o] = float(total);
  }
  // Back through the MLP, last layer first.
  const std::vector<int> sizes = model.layer_sizes();
  const int layers = int(sizes.size()) - 1;
  d_mlp.assign(model.mlp.size(), 0.0f);
  std::vector<size_t> weight_at(layers), act_at(layers);
  for (int l = 0, w = 0, a = 0; l < layers; ++l) {
    weight_at[l] = size_t(w), act_at[l] = size_t(a);
    w += sizes[l + 1] * (sizes[l] + 1);
    a += sizes[l + 1];
  }
  std::vector<float> grad = d_out;  // ∂L/∂(layer l's output, before its ReLU)
  for (int l = layers - 1; l >= 0; --l) {
    const int n_in = sizes[l], n_out = sizes[l + 1];
    const float* input = l == 0 ? e.data() : activations.data() + act_at[l - 1];
    const float* w = model.mlp.data() + weight_at[l];
    float* dw = d_mlp.data() + weight_at[l];
    std::vector<float> d_input(n_in, 0.0f);
    for (int o = 0; o < n_out; ++o) {
      const float g = grad[o];
      if (g == 0.0f) continue;
      dw[size_t(n_out) * n_in + o] += g;  // bias
      for (int i = 0; i < n_in; ++i) {
        dw[size_t(o) * n_in + i] += g * input[i];
        d_input[i] += g * w[size_t(o) * n_in + i];
      }
    }
    if (l > 0)  // through the previous layer's ReLU
      for (int i = 0; i < n_in; ++i) d_input[i] = input[i] > 0.0f ? d_input[i] : 0.0f;
    grad = std::move(d_input);
  }
  d_embedding = std::move(grad);
}

double background_alpha_loss(std::span<const float> bg, std::span<const float> target, Layer s, Layer d, int width,
                             int height, const BackgroundSettings& settings, std::span<float> d_static_alpha,
                             std::span<const float> keep) {
  const size_t pixels = size_t(width) * size_t(height);
  if (bg.size() != 3 * pixels || target.size() != 3 * pixels || s.alpha.size() != pixels ||
      d_static_alpha.size() != pixels || (!d.alpha.empty() && d.alpha.size() != pixels) ||
      (!keep.empty() && keep.size() != pixels))
    throw std::invalid_argument("background_alpha_loss: image sizes disagree");
  std::vector<uint8_t> explained(pixels);
  for (size_t p = 0; p < pixels; ++p) {
    float err = 0;
    for (int c = 0; c < 3; ++c) err += std::abs(target[3 * p + c] - bg[3 * p + c]);
    explained[p] = (keep.empty() || keep[p] > 0) && err / 3.0f < settings.explained_error;
  }
  // The 3×3 box: a lone explained pixel in a textured region is chance, not background.
  // Each kept pixel is clear or covered; ignored ones are in neither set.
  enum : uint8_t { kIgnored = 0, kClear = 1, kCovered = 2 };
  std::vector<uint8_t> cls(pixels, kIgnored);
  size_t n_clear = 0, n_covered = 0;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t p = size_t(y) * width + x;
      if (!keep.empty() && keep[p] == 0) continue;  // ignored: no gradient
      int count = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx >= 0 && yy >= 0 && xx < width && yy < height) count += explained[size_t(yy) * width + xx];
        }
      const bool clear = float(count) / 9.0f > settings.explained_share;
      cls[p] = clear ? kClear : kCovered;
      ++(clear ? n_clear : n_covered);
    }
  // Transparent where clear (λ_bg · mean A), opaque where covered (λ_o · mean (1 − A)).
  const float w_clear = n_clear ? settings.lambda_alpha / float(n_clear) : 0.0f;
  const float w_covered = n_covered ? settings.lambda_opaque / float(n_covered) : 0.0f;
  double sum_clear = 0, sum_covered = 0;
  for (size_t p = 0; p < pixels; ++p) {
    if (cls[p] == kIgnored) continue;
    const float ad = d.alpha.empty() ? 0.0f : d.alpha[p];
    const float a = ad + (1.0f - ad) * s.alpha[p];
    if (cls[p] == kClear) {
      sum_clear += a;
      d_static_alpha[p] += w_clear * (1.0f - ad);
    } else {
      sum_covered += 1.0f - a;
      d_static_alpha[p] -= w_covered * (1.0f - ad);
    }
  }
  double value = 0;
  if (n_clear) value += double(settings.lambda_alpha) * sum_clear / double(n_clear);
  if (n_covered) value += double(settings.lambda_opaque) * sum_covered / double(n_covered);
  return value;
}

}  // namespace desplat
