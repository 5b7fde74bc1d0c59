// 0.8·L1 + 0.2·(1 − SSIM) with a hand-written gradient. SSIM's five local statistics
// come from a separable 11-tap Gaussian filter over the valid region; the gradient
// goes back through the same filter transposed (a "full" scatter).
#include "desplat/train/loss.hpp"

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace desplat {
namespace {

constexpr int kWindow = 11;
constexpr double kSigma = 1.5;
constexpr float kC1 = 0.01f * 0.01f, kC2 = 0.03f * 0.03f;

struct Window {
  float w[kWindow];
  Window() {
    double sum = 0, tmp[kWindow];
    for (int i = 0; i < kWindow; ++i) sum += tmp[i] = std::exp(-0.5 * (i - 5) * (i - 5) / (kSigma * kSigma));
    for (int i = 0; i < kWindow; ++i) w[i] = float(tmp[i] / sum);
  }
};
const Window kGauss;

// Valid separable filtering of a planar image [h, w] → [h − 10, w − 10].
void filter_valid(const std::vector<float>& in, int w, int h, std::vector<float>& tmp, std::vector<float>& out) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  tmp.resize(size_t(h) * ow);
  out.resize(size_t(oh) * ow);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < ow; ++x) {
      float s = 0;
      for (int k = 0; k < kWindow; ++k) s += kGauss.w[k] * in[size_t(y) * w + x + k];
      tmp[size_t(y) * ow + x] = s;
    }
  for (int y = 0; y < oh; ++y)
    for (int x = 0; x < ow; ++x) {
      float s = 0;
      for (int k = 0; k < kWindow; ++k) s += kGauss.w[k] * tmp[size_t(y + k) * ow + x];
      out[size_t(y) * ow + x] = s;
    }
}

// Transpose of filter_valid: scatters [h − 10, w − 10] back to [h, w].
void filter_valid_transposed(const std::vector<float>& in, int w, int h, std::vector<float>& tmp,
                             std::vector<float>& out) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  tmp.assign(size_t(h) * ow, 0.0f);
  out.assign(size_t(h) * w, 0.0f);
  for (int y = 0; y < oh; ++y)
    for (int x = 0; x < ow; ++x)
      for (int k = 0; k < kWindow; ++k) tmp[size_t(y + k) * ow + x] += kGauss.w[k] * in[size_t(y) * ow + x];
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < ow; ++x)
      for (int k = 0; k < kWindow; ++k) out[size_t(y) * w + x + k] += kGauss.w[k] * tmp[size_t(y) * ow + x];
}

void check_sizes(size_t a, size_t b, int width, int height) {
  if (width < kWindow || height < kWindow)
    throw std::invalid_argument("SSIM needs images of at least 11x11 pixels, got " + std::to_string(width) + "x" +
                                std::to_string(height));
  if (a != size_t(width) * height * 3 || b != a)
    throw std::invalid_argument("loss: image buffers do not match " + std::to_string(width) + "x" +
                                std::to_string(height) + "x3");
}

// Mean SSIM over valid positions and channels; when d_x is given, adds
// scale·∂SSIM/∂x to it ([H, W, 3]).
double ssim_and_gradient(std::span<const float> x, std::span<const float> y, int w, int h, float scale,
                         float* d_x) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  const size_t n_out = size_t(ow) * oh;
  const double count = double(n_out) * 3;
  double total = 0;
#pragma omp parallel for schedule(static, 1) reduction(+ : total)
  for (int ch = 0; ch < 3; ++ch) {
    std::vector<float> px(size_t(w) * h), py(px.size()), pxx(px.size()), pyy(px.size()), pxy(px.size());
    for (size_t p = 0; p < px.size(); ++p) {
      px[p] = x[3 * p + ch], py[p] = y[3 * p + ch];
      pxx[p] = px[p] * px[p], pyy[p] = py[p] * py[p], pxy[p] = px[p] * py[p];
    }
    std::vector<float> tmp, mx, my, exx, eyy, exy;
    filter_valid(px, w, h, tmp, mx);
    filter_valid(py, w, h, tmp, my);
    filter_valid(pxx, w, h, tmp, exx);
    filter_valid(pyy, w, h, tmp, eyy);
    filter_valid(pxy, w, h, tmp, exy);
    std::vector<float> dmx(d_x ? n_out : 0), dexx(dmx.size()), dexy(dmx.size());
    double channel_sum = 0;
    for (size_t q = 0; q < n_out; ++q) {
      const float mux = mx[q], muy = my[q];
      const float sxx = exx[q] - mux * mux, syy = eyy[q] - muy * muy, sxy = exy[q] - mux * muy;
      const float n1 = 2 * mux * muy + kC1, n2 = 2 * sxy + kC2;
      const float d1 = mux * mux + muy * muy + kC1, d2 = sxx + syy + kC2;
      const float s = (n1 * n2) / (d1 * d2);
      channel_sum += s;
      if (!d_x) continue;
      // Partials of s in μx, σx², σxy, then through σx² = E[x²] − μx², σxy = E[xy] − μxμy.
      const float ds_dmux = 2 * muy * n2 / (d1 * d2) - s * 2 * mux / d1;
      const float ds_dsxx = -s / d2;
      const float ds_dsxy = 2 * n1 / (d1 * d2);
      const float g = float(scale / count);
      dmx[q] = g * (ds_dmux - 2 * mux * ds_dsxx - muy * ds_dsxy);
      dexx[q] = g * ds_dsxx;
      dexy[q] = g * ds_dsxy;
    }
    total += channel_sum;
    if (!d_x) continue;
    std::vector<float> gmx, gxx, gxy;
    filter_valid_transposed(dmx, w, h, tmp, gmx);
    filter_valid_transposed(dexx, w, h, tmp, gxx);
    filter_valid_transposed(dexy, w, h, tmp, gxy);
    for (size_t p = 0; p < px.size(); ++p) d_x[3 * p + ch] += gmx[p] + 2 * px[p] * gxx[p] + py[p] * gxy[p];
  }
  return total / count;
}

}  // namespace

PhotometricLoss photometric_loss(std::span<const float> render, std::span<const float> target, int width,
                                 int height, float ssim_lambda, std::span<float> d_render) {
  check_sizes(render.size(), target.size(), width, height);
  const bool grad = !d_render.empty();
  if (grad && d_render.size() != render.size()) throw std::invalid_argument("loss: gradient buffer has the wrong size");
  const double n = double(render.size());
  const float l1_scale = float((1.0 - ssim_lambda) / n);
  double l1 = 0;
  for (size_t i = 0; i < render.size(); ++i) {
    const float diff = render[i] - target[i];
    l1 += std::abs(diff);
    if (grad) d_render[i] = diff > 0 ? l1_scale : (diff < 0 ? -l1_scale : 0.0f);
  }
  l1 /= n;
  // loss contains −λ·SSIM, so SSIM's gradient enters with scale −λ.
  const double s = ssim_and_gradient(render, target, width, height, -ssim_lambda, grad ? d_render.data() : nullptr);
  return {(1.0 - ssim_lambda) * l1 + ssim_lambda * (1.0 - s), l1, s};
}

double ssim(std::span<const float> a, std::span<const float> b, int width, int height) {
  check_sizes(a.size(), b.size(), width, height);
  return ssim_and_gradient(a, b, width, height, 0.0f, nullptr);
}

double psnr(std::span<const float> a, std::span<const float> b) {
  if (a.size() != b.size() || a.empty()) throw std::invalid_argument("psnr: image sizes differ or are empty");
  double mse = 0;
  for (size_t i = 0; i < a.size(); ++i) mse += double(a[i] - b[i]) * (a[i] - b[i]);
  mse /= double(a.size());
  return mse > 0 ? -10.0 * std::log10(mse) : INFINITY;
}

}  // namespace desplat
