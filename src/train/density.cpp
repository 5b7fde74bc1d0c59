// Split / duplicate / cull / opacity reset (docs/METHOD.md §7).
#include "desplat/train/density.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace desplat {
namespace {

float max_log_scale(const GaussianSet& g, size_t i) {
  return std::max({g.log_scales[3 * i], g.log_scales[3 * i + 1], g.log_scales[3 * i + 2]});
}
float max_scale(const GaussianSet& g, size_t i) { return std::exp(max_log_scale(g, i)); }
float logit(float p) { return std::log(p / (1 - p)); }

template <typename T>
void append_row(std::vector<T>& dst, const std::vector<T>& src, size_t i, int stride) {
  dst.insert(dst.end(), src.begin() + i * stride, src.begin() + (i + 1) * stride);
}

}  // namespace

namespace {
// An empty set with g's layout (colour mode, SH degree, feature size).
GaussianSet empty_like(const GaussianSet& g) {
  GaussianSet out;
  out.color_mode = g.color_mode;
  out.sh_degree = g.sh_degree;
  out.feature_dim = g.feature_dim;
  return out;
}
}  // namespace

GaussianSet copy_rows(const GaussianSet& g, const std::vector<uint8_t>& mask) {
  GaussianSet out = empty_like(g);
  for (size_t i = 0; i < g.size(); ++i) {
    if (!mask[i]) continue;
    for (const ParamGroupInfo& info : kParamGroupTable)
      append_row(out.*info.values, g.*info.values, i, group_width(info, g));
  }
  return out;
}

// Each selected Gaussian becomes `samples` Gaussians placed at draws from itself,
// with scales divided by `scale_factor`; the draws are ordered sample-major (all
// selected Gaussians for sample 0, then sample 1), as Splatfacto's repeat() does.
GaussianSet split_samples(const GaussianSet& g, const std::vector<uint8_t>& mask, int samples, float scale_factor,
                          std::mt19937_64& rng) {
  const GaussianSet base = copy_rows(g, mask);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  GaussianSet out = empty_like(g);
  const float log_factor = std::log(scale_factor);
  for (int s = 0; s < samples; ++s) {
    GaussianSet copy = base;
    for (size_t i = 0; i < copy.size(); ++i) {
      Eigen::Quaternionf q(copy.quats[4 * i], copy.quats[4 * i + 1], copy.quats[4 * i + 2], copy.quats[4 * i + 3]);
      if (q.squaredNorm() > 0) q.normalize();
      const Eigen::Vector3f scale(std::exp(copy.log_scales[3 * i]), std::exp(copy.log_scales[3 * i + 1]),
                                  std::exp(copy.log_scales[3 * i + 2]));
      Eigen::Vector3f z;
      for (int k = 0; k < 3; ++k) z[k] = normal(rng);
      const Eigen::Vector3f offset = q.toRotationMatrix() * scale.cwiseProduct(z);
      for (int k = 0; k < 3; ++k) {
        copy.means[3 * i + k] += offset[k];
        copy.log_scales[3 * i + k] -= log_factor;
      }
    }
    for (const ParamGroupInfo& info : kParamGroupTable)
      (out.*info.values).insert((out.*info.values).end(), (copy.*info.values).begin(), (copy.*info.values).end());
  }
  return out;
}

bool opacity_reset_due(const DensifySettings& s, int64_t step) {
  const int64_t reset_interval = int64_t(s.reset_alpha_every) * s.refine_every;
  return s.enabled && step > s.warmup && step % s.refine_every == 0 && step < s.stop_split_at &&
         step % reset_interval == s.refine_every;
}

RefineReport refine_gaussians(TrainableGaussians& g, const DensifySettings& s, int64_t step, int image_size,
                              int num_train_views, std::mt19937_64& rng) {
  if (!s.enabled || step <= s.warmup || step % s.refine_every != 0) return {};
  const int64_t reset_interval = int64_t(s.reset_alpha_every) * s.refine_every;
  const bool densify = step < s.stop_split_at && step % reset_interval > num_train_views + s.refine_every;
  RefineReport report = apply_density_control(g, s, step, image_size, densify, false, rng);
  if (opacity_reset_due(s, step)) {
    const float cap = logit(2.0f * s.cull_alpha);
    const int opacity = int(ParamGroup::OpacityLogits);
    for (size_t i = 0; i < g.size(); ++i) {
      g.params.opacity_logits[i] = std::min(g.params.opacity_logits[i], cap);
      g.adam_m[opacity][i] = g.adam_v[opacity][i] = 0.0f;
    }
    report.opacity_reset = true;
  }
  return report;
}

RefineReport& RefineReport::operator+=(const RefineReport& r) {
  split += r.split, duplicated += r.duplicated, culled += r.culled;
  high_gradient += r.high_gradient, held_back += r.held_back, on_camera_path += r.on_camera_path;
  for (int b = 0; b < kGradientRatioBins; ++b) gradient_ratio_bins[b] += r.gradient_ratio_bins[b];
  opacity_reset = opacity_reset || r.opacity_reset;
  ran = ran || r.ran;
  return *this;
}

namespace {
int gradient_ratio_bin(float ratio) {
  if (!(ratio >= 0.5f)) return 0;
  if (ratio < 1.0f) return 1;
  if (ratio < 2.0f) return 2;
  if (ratio < 4.0f) return 3;
  return 4;
}
}  // namespace

RefineReport apply_density_control(TrainableGaussians& g, const DensifySettings& s, int64_t step, int image_size,
                                   bool densify, bool cull_unseen, std::mt19937_64& rng, int64_t max_new) {
  RefineReport report;
  report.ran = true;
  const int64_t reset_interval = int64_t(s.reset_alpha_every) * s.refine_every;
  const size_t n = g.size();
  // Rows [0, n) are the Gaussians the statistics describe; densification appends after them.
  std::vector<uint8_t> unseen(n, 0);
  if (cull_unseen)
    for (size_t i = 0; i < n; ++i) unseen[i] = g.max_screen_radius[i] == 0.0f;
  std::vector<uint8_t> remove(n, 0);
  std::vector<float> mean_grad(n);
  std::vector<uint8_t> high(n, 0);
  for (size_t i = 0; i < n; ++i) {
    mean_grad[i] = g.mean_gradient(i, s.stats, image_size);
    high[i] = g.visible_count[i] > 0 && mean_grad[i] > s.grad_threshold;
    report.high_gradient += high[i];
    ++report.gradient_ratio_bins[gradient_ratio_bin(mean_grad[i] / s.grad_threshold)];
  }

  if (densify) {
    const float log_factor = std::log(s.split_scale_factor);
    std::vector<uint8_t> split(n, 0), dup(n, 0);
    for (size_t i = 0; i < n; ++i) {
      const bool big_on_screen = step < s.stop_screen_size_at && g.max_screen_radius[i] > s.split_screen_size;
      const bool big_in_world = max_scale(g.params, i) > s.size_threshold;
      split[i] = s.split_screen_needs_grad ? high[i] && (big_in_world || big_on_screen)
                                           : (high[i] && big_in_world) || big_on_screen;
      // As Splatfacto: a split original shrinks in place before the duplicate test, so a
      // Gaussian split for its screen size (or just above the size threshold) is also
      // duplicated, with the reduced scale.
      const float size_after = std::exp(max_log_scale(g.params, i) - (split[i] ? log_factor : 0.0f));
      dup[i] = high[i] && size_after <= s.size_threshold;
    }
    if (max_new >= 0) {
      // A growth budget: the candidates with the highest mean gradient go first.
      std::vector<size_t> order;
      for (size_t i = 0; i < n; ++i)
        if (split[i] || dup[i]) order.push_back(i);
      std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return mean_grad[a] > mean_grad[b]; });
      int64_t added = 0;
      for (size_t i : order) {
        const int64_t cost = (split[i] ? s.split_samples - 1 : 0) + (dup[i] ? 1 : 0);
        if (added + cost <= max_new) {
          added += cost;
        } else {
          split[i] = dup[i] = 0;
          ++report.held_back;
        }
      }
    }
    const GaussianSet split_set = split_samples(g.params, split, s.split_samples, s.split_scale_factor, rng);
    for (size_t i = 0; i < n; ++i)
      if (split[i])
        for (int k = 0; k < 3; ++k) g.params.log_scales[3 * i + k] -= log_factor;
    const GaussianSet dup_set = copy_rows(g.params, dup);
    report.split = std::count(split.begin(), split.end(), 1);
    report.duplicated = std::count(dup.begin(), dup.end(), 1);
    g.append(split_set);
    g.append(dup_set);
    if (s.inherit_moments) {
      // Rows appended in the order split_samples and copy_rows produce them.
      size_t row = n;
      for (int sample = 0; sample < s.split_samples; ++sample)
        for (size_t i = 0; i < n; ++i)
          if (split[i]) g.copy_moments(row++, i);
      for (size_t i = 0; i < n; ++i)
        if (dup[i]) g.copy_moments(row++, i);
    }
    remove = split;  // the originals of split Gaussians go away
    remove.resize(g.size(), 0);
  }
  // Cull (also after densification has stopped).
  const float min_logit = logit(s.cull_alpha);
  for (size_t i = 0; i < g.size(); ++i) {
    bool cull = g.params.opacity_logits[i] < min_logit || (i < n && unseen[i]);
    if (step > reset_interval) {
      cull = cull || max_scale(g.params, i) > s.cull_scale;
      if (step < s.stop_screen_size_at) cull = cull || g.max_screen_radius[i] > s.cull_screen_size;
    }
    if (cull && !remove[i]) ++report.culled;
    remove[i] = remove[i] || cull;
  }
  std::vector<uint8_t> keep(g.size());
  for (size_t i = 0; i < keep.size(); ++i) keep[i] = !remove[i];
  g.keep(keep);
  g.reset_statistics();
  return report;
}

}  // namespace desplat
