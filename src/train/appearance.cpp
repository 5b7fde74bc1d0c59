// The appearance MLP's forward and backward passes over the visible Gaussians (docs/METHOD.md §10).
#include "desplat/train/appearance.hpp"

#include <omp.h>
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "desplat/train/embedding_mlp.hpp"
#include "desplat/train/trainable.hpp"

namespace desplat {

void AppearanceSettings::validate() const {
  auto positive = [](int v, const char* name) {
    if (v <= 0)
      throw std::invalid_argument(std::string("appearance.") + name + " must be > 0 (got " + std::to_string(v) + ")");
  };
  positive(image_dim, "image_dim");
  positive(fourier_frequencies, "fourier_frequencies");
  positive(hidden_width, "hidden_width");
  positive(hidden_layers, "hidden_layers");
  positive(test_steps, "test_steps");
  // A training rate of 0 freezes its group, as everywhere (train_config_json's rule).
  for (auto [v, name] : {std::pair{lr_mlp, "lr_mlp"}, std::pair{lr_image, "lr_image"}})
    if (!(v >= 0 && std::isfinite(v)))
      throw std::invalid_argument(std::string("appearance.") + name + " must be ≥ 0 (got " + std::to_string(v) + ")");
  if (!(test_lr > 0 && std::isfinite(test_lr)))
    throw std::invalid_argument("appearance.test_lr must be a positive number (got " + std::to_string(test_lr) + ")");
}

std::vector<float> fourier_features(std::span<const float> means, int frequencies) {
  const size_t n = means.size() / 3;
  const int width = 6 * frequencies;
  std::vector<float> out(n * size_t(width), 0.0f);
  if (n == 0) return out;
  constexpr double kTwoPi = 6.283185307179586;
  for (int axis = 0; axis < 3; ++axis) {
    double mean = 0;
    for (size_t i = 0; i < n; ++i) mean += means[3 * i + axis];
    mean /= double(n);
    std::vector<double> magnitude(n);
    for (size_t i = 0; i < n; ++i) magnitude[i] = std::abs(means[3 * i + axis] - mean);
    const size_t q = std::min(n - 1, size_t(std::floor(0.97 * double(n - 1))));
    std::nth_element(magnitude.begin(), magnitude.begin() + q, magnitude.end());
    const double scale = magnitude[q] > 0 ? magnitude[q] : 1.0;
    for (size_t i = 0; i < n; ++i) {
      const double x = (means[3 * i + axis] - mean) / scale * 0.5 + 0.5;
      for (int k = 0; k < frequencies; ++k) {
        const double phase = x * kTwoPi * double(1 << k);
        out[i * width + axis * 2 * frequencies + 2 * k] = float(std::sin(phase));
        out[i * width + axis * 2 * frequencies + 2 * k + 1] = float(std::cos(phase));
      }
    }
  }
  return out;
}

std::vector<int> AppearanceModel::layer_sizes() const {
  std::vector<int> sizes{settings.feature_dim() + 3 + settings.image_dim};
  for (int l = 0; l < settings.hidden_layers; ++l) sizes.push_back(settings.hidden_width);
  sizes.push_back(6);
  return sizes;
}

size_t AppearanceModel::mlp_floats() const { return mlp_weight_count(layer_sizes()); }

AppearanceModel::AppearanceModel(const AppearanceSettings& s, size_t views, uint64_t seed) : settings(s) {
  settings.validate();
  std::mt19937_64 rng(seed);
  mlp = initial_mlp_weights(layer_sizes(), rng);
  image_embeddings = initial_embeddings(views * size_t(settings.image_dim), rng);
  mlp_m.assign(mlp.size(), 0.0f);
  mlp_v.assign(mlp.size(), 0.0f);
  embed_m.assign(image_embeddings.size(), 0.0f);
  embed_v.assign(image_embeddings.size(), 0.0f);
}

void AppearanceModel::check_consistent() const { check_per_image_model(*this, "appearance"); }

bool AppearanceModel::adam_update(std::span<const float> d_mlp, std::span<const float> d_embeddings) {
  if (d_mlp.size() != mlp.size() || d_embeddings.size() != image_embeddings.size())
    throw std::logic_error("appearance adam_update: gradient sizes differ from the parameters");
  if (!all_finite(d_mlp) || !all_finite(d_embeddings)) return false;
  const AdamSettings a;
  const AdamBiasCorrection bc = advance_adam_step(adam_step, a);
  const double bc1 = bc.bc1;
  const float sqrt_bc2 = bc.sqrt_bc2;
  adam_span(mlp.data(), mlp_m.data(), mlp_v.data(), d_mlp.data(), mlp.size(), float(settings.lr_mlp / bc1), sqrt_bc2,
            a);
  adam_span(image_embeddings.data(), embed_m.data(), embed_v.data(), d_embeddings.data(), image_embeddings.size(),
            float(settings.lr_image / bc1), sqrt_bc2, a);
  return true;
}

namespace {

using RowMat = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstMap = Eigen::Map<const RowMat>;
using Map = Eigen::Map<RowMat>;

// The visible rows are cut into this many slabs whatever the thread count (each slab's
// weight gradient is summed on its own, then the slabs in order): bit-identical results.
constexpr int kSlabs = 16;
constexpr int64_t kBatch = 256;  // rows per matrix product inside a slab

// The weights (or a gradient of the same shape) as Eigen-owned matrices: Eigen's products
// sum in an order that can depend on where the data sits in memory, so the data it multiplies
// always lives in its own (aligned) allocations, never in a mapped std::vector.
struct Layers {
  std::vector<int> sizes;
  std::vector<RowMat> w;              // layer l: [sizes[l+1], sizes[l]]
  std::vector<Eigen::RowVectorXf> b;  // [sizes[l+1]]
  explicit Layers(const AppearanceModel& m) : sizes(m.layer_sizes()) {
    for (size_t l = 0; l + 1 < sizes.size(); ++l) {
      w.push_back(RowMat::Zero(sizes[l + 1], sizes[l]));
      b.push_back(Eigen::RowVectorXf::Zero(sizes[l + 1]));
    }
  }
  Layers(const AppearanceModel& m, const float* flat) : Layers(m) {
    for (size_t l = 0; l < w.size(); ++l) {
      w[l] = ConstMap(flat, w[l].rows(), w[l].cols());
      flat += w[l].size();
      b[l] = Eigen::Map<const Eigen::RowVectorXf>(flat, b[l].size());
      flat += b[l].size();
    }
  }
  int count() const { return int(w.size()); }
  // Adds this gradient into the flat layout.
  void add_to(float* flat) const {
    for (size_t l = 0; l < w.size(); ++l) {
      Map(flat, w[l].rows(), w[l].cols()) += w[l];
      flat += w[l].size();
      Eigen::Map<Eigen::RowVectorXf>(flat, b[l].size()) += b[l];
      flat += b[l].size();
    }
  }
};

// Rows [r0, r1) of the visible set: X = (z, c̄) per row.
RowMat gather_inputs(const GaussianSet& g, const std::vector<int32_t>& rows, int64_t r0, int64_t r1) {
  const int f = g.feature_dim, stride = g.view().color_floats_per_gaussian();
  RowMat x(r1 - r0, f + 3);
  for (int64_t r = r0; r < r1; ++r) {
    const size_t i = size_t(rows[r]);
    for (int k = 0; k < f; ++k) x(r - r0, k) = g.features[i * f + k];
    for (int c = 0; c < 3; ++c) x(r - r0, f + c) = g.colors[i * stride + c];
  }
  return x;
}

// Hidden activations (after ReLU) and the outputs of one batch. `u` = the first layer's
// embedding part plus its bias, the same for every row.
void run_layers(const Layers& net, const RowMat& x, const Eigen::RowVectorXf& u, std::vector<RowMat>& hidden,
                RowMat* out) {
  const int inputs = int(x.cols());
  const int n_hidden = net.count() - 1;
  hidden.resize(n_hidden);
  hidden[0].noalias() = x * net.w[0].leftCols(inputs).transpose();
  hidden[0].rowwise() += u;
  hidden[0] = hidden[0].cwiseMax(0.0f);
  for (int l = 1; l < n_hidden; ++l) {
    hidden[l].noalias() = hidden[l - 1] * net.w[l].transpose();
    hidden[l].rowwise() += net.b[l];
    hidden[l] = hidden[l].cwiseMax(0.0f);
  }
  if (!out) return;
  out->noalias() = hidden[n_hidden - 1] * net.w[n_hidden].transpose();
  out->rowwise() += net.b[n_hidden];
}

// u = W0[:, inputs:] e + b0.
Eigen::RowVectorXf embedding_term(const Layers& net, std::span<const float> e) {
  const Eigen::VectorXf ev = Eigen::Map<const Eigen::VectorXf>(e.data(), Eigen::Index(e.size()));
  return (net.w[0].rightCols(ev.size()) * ev).transpose() + net.b[0];
}

int64_t slab_begin(int64_t rows, int s) { return rows * s / kSlabs; }

void check_inputs(const AppearanceModel& model, std::span<const float> e, const GaussianSet& g) {
  if (int(e.size()) != model.settings.image_dim)
    throw std::invalid_argument("appearance: the image embedding has " + std::to_string(e.size()) +
                                " values, the model expects " + std::to_string(model.settings.image_dim));
  if (g.feature_dim != model.settings.feature_dim() || g.features.size() != g.size() * size_t(g.feature_dim))
    throw std::invalid_argument("appearance: the Gaussians carry " + std::to_string(g.feature_dim) +
                                " features each, the model expects " + std::to_string(model.settings.feature_dim()));
  if (g.color_mode != ColorMode::SphericalHarmonics)
    throw std::invalid_argument("appearance: only SH-coloured (static) Gaussians have an appearance");
}

}  // namespace

void AppearancePass::forward(const AppearanceModel& model, std::span<const float> e, const GaussianSet& g,
                             RasterOutput& fw, int threads) {
  check_inputs(model, e, g);
  const size_t n = g.size();
  rows.clear();
  for (size_t i = 0; i < n; ++i)
    if (fw.visible[i]) rows.push_back(int32_t(i));
  const int64_t count = int64_t(rows.size());
  sh_rgb.assign(size_t(count) * 3, 0.0f);
  active.assign(size_t(count) * 3, 0);
  rgb_scale.assign(3 * n, 0.0f);
  const Layers net(model, model.mlp.data());
  const Eigen::RowVectorXf u = embedding_term(net, e);

#pragma omp parallel for num_threads(threads > 0 ? threads : omp_get_max_threads()) schedule(dynamic, 1)
  for (int s = 0; s < kSlabs; ++s) {
    std::vector<RowMat> hidden;
    RowMat out;
    for (int64_t r0 = slab_begin(count, s); r0 < slab_begin(count, s + 1); r0 += kBatch) {
      const int64_t r1 = std::min(r0 + kBatch, slab_begin(count, s + 1));
      run_layers(net, gather_inputs(g, rows, r0, r1), u, hidden, &out);
      for (int64_t r = r0; r < r1; ++r) {
        const size_t i = size_t(rows[r]);
        for (int c = 0; c < 3; ++c) {
          const float beta = out(r - r0, c), gamma = 1.0f + out(r - r0, 3 + c);
          const float sh = fw.rgb[3 * i + c];
          sh_rgb[3 * r + c] = sh;
          const float toned = gamma * sh + beta;
          // NaN and negative both end at 0 with no gradient.
          const bool on = toned > 0.0f;
          active[3 * r + c] = on;
          fw.rgb[3 * i + c] = on ? toned : 0.0f;
          rgb_scale[3 * i + c] = on ? gamma : 0.0f;
        }
      }
    }
  }
}

void AppearancePass::backward(const AppearanceModel& model, std::span<const float> e, const GaussianSet& g,
                              RasterGradients& grads, int threads) {
  check_inputs(model, e, g);
  const int f = g.feature_dim, stride = g.view().color_floats_per_gaussian();
  const int inputs = f + 3;
  if (grads.rgb.size() != 3 * g.size() || grads.colors.size() != g.colors.size())
    throw std::invalid_argument("appearance backward: the gradients are not those of this set's render");
  grads.features.assign(g.features.size(), 0.0f);
  // A row whose colour reached no pixel (∂L/∂c̃ zero, or clamped, in every channel) adds
  // exactly nothing to any gradient: only the others go through the MLP again.
  std::vector<int32_t> live, live_gaussians;  // index into `rows`; the Gaussian's index
  for (int64_t r = 0; r < int64_t(rows.size()); ++r) {
    const size_t i = size_t(rows[r]);
    bool reached = false;
    for (int c = 0; c < 3; ++c) reached |= active[3 * r + c] && grads.rgb[3 * i + c] != 0.0f;
    if (!reached) continue;
    live.push_back(int32_t(r));
    live_gaussians.push_back(rows[r]);
  }
  const int64_t count = int64_t(live.size());
  const Layers net(model, model.mlp.data());
  const Eigen::RowVectorXf u = embedding_term(net, e);
  std::vector<Layers> slab_grads(kSlabs, Layers(model));
  std::vector<Eigen::RowVectorXf> slab_du(kSlabs, Eigen::RowVectorXf::Zero(net.sizes[1]));

#pragma omp parallel for num_threads(threads > 0 ? threads : omp_get_max_threads()) schedule(dynamic, 1)
  for (int s = 0; s < kSlabs; ++s) {
    Layers& d = slab_grads[s];
    std::vector<RowMat> hidden;
    RowMat d_out, d_h, d_prev;
    for (int64_t r0 = slab_begin(count, s); r0 < slab_begin(count, s + 1); r0 += kBatch) {
      const int64_t r1 = std::min(r0 + kBatch, slab_begin(count, s + 1));
      const RowMat x = gather_inputs(g, live_gaussians, r0, r1);
      run_layers(net, x, u, hidden, nullptr);
      // ∂L/∂o from ∂L/∂c̃: β passes it where the clamp was inactive, γ scales c.
      d_out.resize(r1 - r0, 6);
      for (int64_t q = r0; q < r1; ++q) {
        const int64_t r = live[q];
        const size_t i = size_t(rows[r]);
        for (int c = 0; c < 3; ++c) {
          const float dt = active[3 * r + c] ? grads.rgb[3 * i + c] : 0.0f;
          d_out(q - r0, c) = dt;
          d_out(q - r0, 3 + c) = dt * sh_rgb[3 * r + c];
        }
      }
      // Back through the layers, last to first.
      const int last = net.count() - 1;
      d_h = d_out;
      for (int l = last; l >= 0; --l) {
        const RowMat& w = net.w[l];
        RowMat& dw = d.w[l];
        if (l > 0) {
          dw.noalias() += d_h.transpose() * hidden[l - 1];
          d.b[l] += d_h.colwise().sum();
          d_prev.noalias() = d_h * w;
          d_h = (hidden[l - 1].array() > 0.0f).select(d_prev, 0.0f);
        } else {
          dw.leftCols(inputs).noalias() += d_h.transpose() * x;
          slab_du[s] += d_h.colwise().sum();
          d_prev.noalias() = d_h * w.leftCols(inputs);
        }
      }
      for (int64_t q = r0; q < r1; ++q) {
        const size_t i = size_t(live_gaussians[q]);
        for (int k = 0; k < f; ++k) grads.features[i * f + k] = d_prev(q - r0, k);
        for (int c = 0; c < 3; ++c) grads.colors[i * stride + c] += d_prev(q - r0, f + c);
      }
    }
  }
  // The slabs in order; then the embedding's share of the first layer.
  Layers total(model);
  Eigen::RowVectorXf du = Eigen::RowVectorXf::Zero(net.sizes[1]);
  for (int s = 0; s < kSlabs; ++s) {
    for (int l = 0; l < total.count(); ++l) total.w[l] += slab_grads[s].w[l], total.b[l] += slab_grads[s].b[l];
    du += slab_du[s];
  }
  const Eigen::Index dim = Eigen::Index(e.size());
  const Eigen::RowVectorXf er = Eigen::Map<const Eigen::RowVectorXf>(e.data(), dim);
  total.b[0] += du;
  total.w[0].rightCols(dim) += du.transpose() * er;
  d_mlp.assign(model.mlp.size(), 0.0f);
  total.add_to(d_mlp.data());
  const Eigen::RowVectorXf de = du * net.w[0].rightCols(dim);
  d_embedding.assign(de.data(), de.data() + dim);
}

}  // namespace desplat
