// Row-aligned parameter/moment/statistics storage and the Adam update.
#include "desplat/train/trainable.hpp"

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <stdexcept>
#include <string>

namespace desplat {

TrainableGaussians::TrainableGaussians(GaussianSet initial) : params(std::move(initial)) {
  for (int g = 0; g < kParamGroups; ++g) {
    adam_m[g].assign(param(ParamGroup(g)).size(), 0.0f);
    adam_v[g].assign(param(ParamGroup(g)).size(), 0.0f);
  }
  reset_statistics();
}

int TrainableGaussians::floats_per_gaussian(ParamGroup g) const { return group_width(param_group(g), params); }

namespace {
template <typename T>
void keep_rows(std::vector<T>& v, int stride, const std::vector<uint8_t>& keep) {
  size_t out = 0;
  for (size_t i = 0; i < keep.size(); ++i) {
    if (!keep[i]) continue;
    if (out != i) std::copy_n(v.begin() + i * stride, stride, v.begin() + out * stride);
    ++out;
  }
  v.resize(out * stride);
}
}  // namespace

void TrainableGaussians::keep(const std::vector<uint8_t>& keep_mask) {
  if (keep_mask.size() != size()) throw std::logic_error("keep mask has the wrong length");
  for (int g = 0; g < kParamGroups; ++g) {
    const int stride = floats_per_gaussian(ParamGroup(g));
    keep_rows(param(ParamGroup(g)), stride, keep_mask);
    keep_rows(adam_m[g], stride, keep_mask);
    keep_rows(adam_v[g], stride, keep_mask);
  }
  keep_rows(absgrad_sum, 1, keep_mask);
  keep_rows(visible_count, 1, keep_mask);
  keep_rows(max_screen_radius, 1, keep_mask);
}

void TrainableGaussians::append(const GaussianSet& extra) {
  if (extra.color_mode != params.color_mode || extra.sh_degree != params.sh_degree ||
      extra.feature_dim != params.feature_dim)
    throw std::logic_error("append: color or feature layout differs");
  for (int g = 0; g < kParamGroups; ++g) {
    const std::vector<float>& src = extra.*kParamGroupTable[g].values;
    std::vector<float>& dst = param(ParamGroup(g));
    dst.insert(dst.end(), src.begin(), src.end());
    adam_m[g].resize(dst.size(), 0.0f);
    adam_v[g].resize(dst.size(), 0.0f);
  }
  absgrad_sum.resize(size(), 0.0f);
  visible_count.resize(size(), 0);
  max_screen_radius.resize(size(), 0.0f);
}

void TrainableGaussians::reset_statistics() {
  statistics_empty = true;
  absgrad_sum.assign(size(), 0.0f);
  visible_count.assign(size(), 0);
  max_screen_radius.assign(size(), 0.0f);
}

void TrainableGaussians::copy_moments(size_t dst, size_t src) {
  for (int g = 0; g < kParamGroups; ++g) {
    const size_t stride = size_t(floats_per_gaussian(ParamGroup(g)));
    std::copy_n(adam_m[g].begin() + src * stride, stride, adam_m[g].begin() + dst * stride);
    std::copy_n(adam_v[g].begin() + src * stride, stride, adam_v[g].begin() + dst * stride);
  }
}

namespace {
// The larger screen radius [px] of a projected Gaussian: 3·√λmax of its 2D covariance
// (from the conic, the covariance's inverse: λmax(Σ) = 1 / λmin(conic)), or the larger of
// the rasterizer's per-axis extents.
float screen_radius_px(const RasterOutput& fw, size_t i, bool from_eigenvalue) {
  if (!from_eigenvalue) return float(std::max(fw.radii[2 * i], fw.radii[2 * i + 1]));
  const double a = fw.conics[3 * i], b = fw.conics[3 * i + 1], c = fw.conics[3 * i + 2];
  const double lambda_min = 0.5 * (a + c) - std::sqrt(0.25 * (a - c) * (a - c) + b * b);
  if (!(lambda_min > 0)) return float(std::max(fw.radii[2 * i], fw.radii[2 * i + 1]));
  return float(std::ceil(3.0 * std::sqrt(1.0 / lambda_min)));
}
}  // namespace

void TrainableGaussians::accumulate_statistics(const RasterOutput& fw, const RasterGradients& grads,
                                               const StatisticsRules& rules, float view_scale) {
  const int image_size = std::max(fw.width, fw.height);
  const float inv_size = 1.0f / float(image_size);
  const float grad_scale = rules.normalize_each_step ? 0.5f * float(image_size) : 1.0f;
  // Splatfacto: the first step after a reset counts every Gaussian once (with a zero
  // gradient where it was not visible); later steps count visible ones only. Authors:
  // every count starts at 1.
  const bool first = statistics_empty;
  statistics_empty = false;
  // Every Gaussian's statistics are its own: the rows go to the threads.
  const int64_t n = static_cast<int64_t>(size());
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) {
    if (first && rules.visible_count_from_one) visible_count[i] += 1;
    if (!fw.visible[i] && !(first && !rules.visible_count_from_one)) continue;
    absgrad_sum[i] += grads.absgrad[i] * view_scale * grad_scale;
    visible_count[i] += 1;
    if (!fw.visible[i]) continue;
    const float r = screen_radius_px(fw, i, rules.radius_from_eigenvalue) * inv_size;
    max_screen_radius[i] = std::max(max_screen_radius[i], r);
  }
}

float TrainableGaussians::mean_gradient(size_t i, const StatisticsRules& rules, int image_size) const {
  if (visible_count[i] == 0) return 0.0f;
  const float mean = absgrad_sum[i] / float(visible_count[i]);
  return rules.normalize_each_step ? mean : mean * 0.5f * float(image_size);
}

namespace {
// One value's Adam update; returns 1 if the value or a moment is no longer finite. Branch-free
// (|x| <= FLT_MAX is false for ±Inf and NaN), so the loops that inline it vectorize, and every
// loop computes the same expression.
inline int adam_value(float& p, float& m, float& v, float g, float step_size, float sqrt_bc2, const AdamSettings& a) {
  m = a.beta1 * m + (1 - a.beta1) * g;
  v = a.beta2 * v + (1 - a.beta2) * g * g;
  p -= step_size * m / (std::sqrt(v) / sqrt_bc2 + a.eps);
  return int(!(std::abs(p) <= FLT_MAX)) | int(!(std::abs(m) <= FLT_MAX)) | int(!(std::abs(v) <= FLT_MAX));
}
}  // namespace

bool adam_span(float* p, float* m, float* v, const float* g, size_t n, float step_size, float sqrt_bc2,
               const AdamSettings& a) {
  int bad = 0;
#pragma omp simd reduction(| : bad)
  for (size_t i = 0; i < n; ++i) bad |= adam_value(p[i], m[i], v[i], g[i], step_size, sqrt_bc2, a);
  return bad != 0;
}

namespace {
// A Gaussian's colour floats at most: SH degree 3 (GaussianParams::validate).
constexpr int kMaxColorFloats = 3 * 16;

// The first `width` floats of each of `rows` rows of `stride` floats, the float at lane k
// with step size lane_step[k]: one vectorized loop per row (two spans of 3 and 45 floats per
// row would cost a call and a scalar tail each). kWidth > 0 fixes the width at compile time,
// so a row is a few whole or masked vector operations rather than a loop with a scalar tail.
template <int kWidth>
bool adam_rows(float* p, float* m, float* v, const float* g, int64_t rows, int stride, int width,
               const float* lane_step, float sqrt_bc2, const AdamSettings& a) {
  if constexpr (kWidth > 0) width = kWidth;
  int bad = 0;
  for (int64_t r = 0; r < rows; ++r) {
    const size_t o = size_t(r) * size_t(stride);
    float* pr = p + o;
    float* mr = m + o;
    float* vr = v + o;
    const float* gr = g + o;
#pragma omp simd reduction(| : bad)
    for (int k = 0; k < width; ++k) bad |= adam_value(pr[k], mr[k], vr[k], gr[k], lane_step[k], sqrt_bc2, a);
  }
  return bad != 0;
}

// adam_rows with the width fixed for SH degrees 0, 1 and 3 (3, 12 and 48 floats); degree 2's 27
// and any other width run generically (a fixed 27 is slower than the generic loop, bench_adam).
bool adam_sh_rows(float* p, float* m, float* v, const float* g, int64_t rows, int stride, int width,
                  const float* lane_step, float sqrt_bc2, const AdamSettings& a) {
  switch (width) {
    case 3:
      return adam_rows<3>(p, m, v, g, rows, stride, width, lane_step, sqrt_bc2, a);
    case 12:
      return adam_rows<12>(p, m, v, g, rows, stride, width, lane_step, sqrt_bc2, a);
    case 48:
      return adam_rows<48>(p, m, v, g, rows, stride, width, lane_step, sqrt_bc2, a);
    default:
      return adam_rows<0>(p, m, v, g, rows, stride, width, lane_step, sqrt_bc2, a);
  }
}
}  // namespace

AdamBiasCorrection advance_adam_step(int64_t& step, const AdamSettings& a, int views) {
  step += views;
  const double bc2 = 1.0 - std::pow(double(a.beta2), double(step));
  return {1.0 - std::pow(double(a.beta1), double(step)), float(std::sqrt(bc2))};
}

AdamSettings batch_adam_settings(const AdamSettings& a, int views) {
  if (views == 1) return a;
  AdamSettings out = a;
  out.beta1 = float(std::pow(double(a.beta1), double(views)));
  out.beta2 = float(std::pow(double(a.beta2), double(views)));
  return out;
}

bool all_finite(std::span<const float> values) {
  return std::all_of(values.begin(), values.end(), [](float x) { return std::isfinite(x); });
}

namespace {
bool row_finite(const float* p, const float* m, const float* v, int width) {
  for (int k = 0; k < width; ++k)
    if (!(std::isfinite(p[k]) && std::isfinite(m[k]) && std::isfinite(v[k]))) return false;
  return true;
}
}  // namespace

void TrainableGaussians::adam_update(const RasterGradients& grads, const LearningRates& lr, const AdamSettings& adam,
                                     int trained_color_floats, std::span<const uint8_t> rows_to_update, int views) {
  if (views < 1) throw std::logic_error("adam_update: a step covers at least one view");
  const AdamBiasCorrection bc = advance_adam_step(adam_step, adam, views);
  const AdamSettings a = batch_adam_settings(adam, views);
  const double bc1 = bc.bc1;
  const float sqrt_bc2 = bc.sqrt_bc2;
  const int64_t n = static_cast<int64_t>(size());
  nonfinite_groups.clear();
  // Rows in blocks: each block's groups are updated by one thread (the result does not
  // depend on the thread count: every value's update is independent of the others).
  constexpr int64_t kBlock = 512;
  const int64_t blocks = (n + kBlock - 1) / kBlock;
  int any_bad = 0;
  for (int g = 0; g < kParamGroups; ++g) {
    const ParamGroupInfo& info = kParamGroupTable[g];
    if ((grads.*info.grads).size() != param(info.id).size())
      throw std::logic_error("adam_update: gradient size differs from parameters");
  }
  const bool selective = !rows_to_update.empty();
  if (selective && rows_to_update.size() != size_t(n))
    throw std::logic_error("adam_update: the row selection has " + std::to_string(rows_to_update.size()) +
                           " flags for " + std::to_string(n) + " Gaussians");
  // Updates rows [row0, row0 + rows) of every group; returns whether a value went non-finite.
  auto update_run = [&](int64_t row0, int64_t rows) {
    bool bad = false;
    for (int g = 0; g < kParamGroups; ++g) {
      const ParamGroupInfo& info = kParamGroupTable[g];
      const int stride = floats_per_gaussian(info.id);
      const size_t first = size_t(row0) * stride;
      float* p = param(info.id).data() + first;
      float* m = adam_m[g].data() + first;
      float* v = adam_v[g].data() + first;
      const float* grad = (grads.*info.grads).data() + first;
      const float step_size = float(lr.*info.rate / bc1);
      const bool sh = info.id == ParamGroup::Colors && params.color_mode == ColorMode::SphericalHarmonics;
      if (!sh) {
        bad |= adam_span(p, m, v, grad, size_t(rows) * stride, step_size, sqrt_bc2, a);
        continue;
      }
      // SH colours: the DC coefficient (3 floats) at its rate, the trained higher bands at
      // theirs. Bands above the active degree have had zero gradient since the start of the
      // run, so their moments are zero and Adam would leave them unchanged: they are skipped.
      const int trained = std::clamp(trained_color_floats < 0 ? stride : trained_color_floats, 3, stride);
      if (trained > kMaxColorFloats) throw std::logic_error("adam_update: more colour floats than SH degree 3 has");
      std::array<float, kMaxColorFloats> lane_step;
      for (int k = 0; k < trained; ++k) lane_step[size_t(k)] = k < 3 ? step_size : float(lr.colors_rest / bc1);
      bad |= adam_sh_rows(p, m, v, grad, rows, stride, trained, lane_step.data(), sqrt_bc2, a);
    }
    return bad;
  };
#pragma omp parallel for schedule(static) reduction(| : any_bad)
  for (int64_t b = 0; b < blocks; ++b) {
    const int64_t block_end = std::min(n, (b + 1) * kBlock);
    bool bad = false;
    // Each maximal run of selected rows is one span (the whole block when nothing is
    // selected): every value's arithmetic is the same either way.
    for (int64_t row0 = b * kBlock; row0 < block_end;) {
      if (selective && !rows_to_update[size_t(row0)]) {
        ++row0;
        continue;
      }
      int64_t run_end = row0 + 1;
      while (run_end < block_end && (!selective || rows_to_update[size_t(run_end)])) ++run_end;
      bad |= update_run(row0, run_end - row0);
      row0 = run_end;
    }
    any_bad |= int(bad);
  }
  if (!any_bad) return;
  // Rare: name the rows and groups that went non-finite.
  nonfinite_groups.assign(size(), 0);
  for (int64_t i = 0; i < n; ++i)
    for (int g = 0; g < kParamGroups; ++g) {
      const int w = floats_per_gaussian(ParamGroup(g));
      const size_t o = size_t(i) * w;
      if (!row_finite(param(ParamGroup(g)).data() + o, adam_m[g].data() + o, adam_v[g].data() + o, w))
        nonfinite_groups[i] |= uint8_t(1u << g);
    }
}

void TrainableGaussians::check_consistent() const {
  const size_t n = size();
  for (int g = 0; g < kParamGroups; ++g) {
    const size_t want = n * floats_per_gaussian(ParamGroup(g));
    if (param(ParamGroup(g)).size() != want || adam_m[g].size() != want || adam_v[g].size() != want)
      throw std::logic_error(std::string("parameter group ") + kParamGroupTable[g].name + " is out of step with " +
                             std::to_string(n) + " Gaussians");
  }
  if (absgrad_sum.size() != n || visible_count.size() != n || max_screen_radius.size() != n)
    throw std::logic_error("densification statistics are out of step with the Gaussians");
}

}  // namespace desplat
