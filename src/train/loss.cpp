// 0.8·L1 + 0.2·(1 − SSIM) with a hand-written gradient. SSIM's five local statistics
// come from a separable 11-tap Gaussian filter over the valid region; the gradient
// goes back through the same filter transposed (a "full" scatter).
#include "desplat/train/loss.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace desplat {
namespace {

constexpr int kWindow = kSsimWindow;
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

// dst[x] = Σ_i weight[i]·src[i][x] for x in [0, count), each sum started at 0 and added in
// tap order i = 0, 1, …, n − 1. Blocks of 16 outputs keep their sums in registers across
// the taps (a loop over x inside each tap loads and stores dst once per tap). Every output
// goes through the same vector loop, the last block overlapping the one before it, so each
// sum is contracted to fused multiply-adds the same way: a scalar tail was not.
void weighted_sum_of_rows(const float* const* src, const float* weight, int n, int count, float* dst) {
  constexpr int kBlock = 16;
  auto block = [&](int x, int width) {
    float acc[kBlock] = {};
    for (int i = 0; i < n; ++i)
#pragma omp simd
      for (int j = 0; j < width; ++j) acc[j] += weight[i] * src[i][x + j];
    for (int j = 0; j < width; ++j) dst[x + j] = acc[j];
  };
  if (count < kBlock) return block(0, count);
  for (int x = 0; x + kBlock <= count; x += kBlock) block(x, kBlock);
  if (count % kBlock) block(count - kBlock, kBlock);
}

// Valid separable filtering of a planar image [h, w] → [h − 10, w − 10]. Every output
// is Σ_k w[k]·in[…+k] summed in order k = 0…10. Rows are split over the threads.
void filter_valid(const float* in, int w, int h, float* tmp, float* out) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    const float* row = in + size_t(y) * w;
    const float* taps[kWindow];
    for (int k = 0; k < kWindow; ++k) taps[k] = row + k;
    weighted_sum_of_rows(taps, kGauss.w, kWindow, ow, tmp + size_t(y) * ow);
  }
#pragma omp parallel for schedule(static)
  for (int y = 0; y < oh; ++y) {
    const float* taps[kWindow];
    for (int k = 0; k < kWindow; ++k) taps[k] = tmp + size_t(y + k) * ow;
    weighted_sum_of_rows(taps, kGauss.w, kWindow, ow, out + size_t(y) * ow);
  }
}

// Transpose of filter_valid: scatters [h − 10, w − 10] back to [h, w], written as the
// equivalent gather. Each output sums its terms in the order of their source position
// (row-major), as the scatter would: taps k = 10…0 over the valid sources.
void filter_valid_transposed(const float* in, int w, int h, float* tmp, float* out) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  float reversed[kWindow];  // reversed[i] = w[10 − i]: the taps in source order
  for (int i = 0; i < kWindow; ++i) reversed[i] = kGauss.w[kWindow - 1 - i];
  // Vertical: tmp[Y] = Σ_{y = Y−k valid} w[k]·in[y], sources y ascending (k descending).
#pragma omp parallel for schedule(static)
  for (int Y = 0; Y < h; ++Y) {
    const int k_hi = std::min(kWindow - 1, Y), k_lo = std::max(0, Y - (oh - 1));
    const float* taps[kWindow];
    for (int k = k_hi; k >= k_lo; --k) taps[k_hi - k] = in + size_t(Y - k) * ow;
    weighted_sum_of_rows(taps, reversed + (kWindow - 1 - k_hi), k_hi - k_lo + 1, ow, tmp + size_t(Y) * ow);
  }
  // Horizontal: out[X] = Σ_{x = X−k valid} w[k]·tmp[x], sources x ascending (k descending).
  // Still one pass per tap: a blocked form, with its edge columns summed one by one, changed
  // the gradient's bits (not traced; docs/bench/issue16_speed.md).
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    float* o = out + size_t(y) * w;
    const float* t = tmp + size_t(y) * ow;
    for (int X = 0; X < w; ++X) o[X] = 0.0f;
    for (int k = kWindow - 1; k >= 0; --k)
#pragma omp simd
      for (int x = 0; x < ow; ++x) o[x + k] += kGauss.w[k] * t[x];
  }
}

void check_sizes(size_t a, size_t b, int width, int height) {
  if (width < kWindow || height < kWindow)
    throw std::invalid_argument("SSIM needs images of at least 11x11 pixels, got " + std::to_string(width) + "x" +
                                std::to_string(height));
  if (a != size_t(width) * height * 3 || b != a)
    throw std::invalid_argument("loss: image buffers do not match " + std::to_string(width) + "x" +
                                std::to_string(height) + "x3");
}

// Scratch for one SSIM evaluation, kept between calls (one per thread that calls the loss)
// so a training step allocates nothing.
struct SsimScratch {
  std::vector<float> px, py, pxx, pyy, pxy, tmp, mx, my, exx, eyy, exy, s, dmx, dexx, dexy, gmx, gxx, gxy;
};

// Mean SSIM over valid positions and channels; when d_x is given, adds
// scale·∂SSIM/∂x to it ([H, W, 3]). The channels run one after another, each filter
// split over the threads by rows.
// With `keep` ([H, W] in {0, 1}) both images are multiplied by it first, so an ignored pixel
// reads 0 in both whatever it holds, and the mean runs over the positions whose window center
// is kept: an ignored pixel has no influence on the value and gets no gradient.
double ssim_and_gradient(std::span<const float> x, std::span<const float> y, int w, int h, float scale,
                         float* d_x, const float* keep = nullptr) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  const size_t n_out = size_t(ow) * oh, n_in = size_t(w) * h;
  constexpr int kHalf = kWindow / 2;
  double kept_positions = double(n_out);
  if (keep) {
    kept_positions = 0;
    for (int qy = 0; qy < oh; ++qy)
      for (int qx = 0; qx < ow; ++qx) kept_positions += keep[size_t(qy + kHalf) * w + qx + kHalf];
    if (kept_positions == 0) return 1.0;  // nothing to compare: no loss, no gradient
  }
  const double count = kept_positions * 3;
  thread_local SsimScratch scratch;
  SsimScratch& b = scratch;  // the calling thread's; the parallel loops below share it
  for (auto* v : {&b.px, &b.py, &b.pxx, &b.pyy, &b.pxy, &b.gmx, &b.gxx, &b.gxy}) v->resize(n_in);
  for (auto* v : {&b.mx, &b.my, &b.exx, &b.eyy, &b.exy, &b.s, &b.dmx, &b.dexx, &b.dexy}) v->resize(n_out);
  b.tmp.resize(size_t(h) * ow);
  double total = 0;
  for (int ch = 0; ch < 3; ++ch) {
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < n_in; ++p) {
      const float k = keep ? keep[p] : 1.0f;
      const float xv = k * x[3 * p + ch], yv = k * y[3 * p + ch];
      b.px[p] = xv, b.py[p] = yv;
      b.pxx[p] = xv * xv, b.pyy[p] = yv * yv, b.pxy[p] = xv * yv;
    }
    filter_valid(b.px.data(), w, h, b.tmp.data(), b.mx.data());
    filter_valid(b.py.data(), w, h, b.tmp.data(), b.my.data());
    filter_valid(b.pxx.data(), w, h, b.tmp.data(), b.exx.data());
    filter_valid(b.pyy.data(), w, h, b.tmp.data(), b.eyy.data());
    filter_valid(b.pxy.data(), w, h, b.tmp.data(), b.exy.data());
    // The per-position SSIM and its partials. Positions are independent, so rows go to the
    // threads and each row vectorizes; then an ignored centre gets s = 0 and no gradient.
    const float g = float(scale / count);
#pragma omp parallel for schedule(static)
    for (int qy = 0; qy < oh; ++qy) {
      const size_t row = size_t(qy) * ow;
      const float *mx = &b.mx[row], *my = &b.my[row], *exx = &b.exx[row], *eyy = &b.eyy[row], *exy = &b.exy[row];
      float *s_out = &b.s[row], *dmx = &b.dmx[row], *dexx = &b.dexx[row], *dexy = &b.dexy[row];
#pragma omp simd
      for (int qx = 0; qx < ow; ++qx) {
        const float mux = mx[qx], muy = my[qx];
        const float sxx = exx[qx] - mux * mux, syy = eyy[qx] - muy * muy, sxy = exy[qx] - mux * muy;
        const float n1 = 2 * mux * muy + kC1, n2 = 2 * sxy + kC2;
        const float d1 = mux * mux + muy * muy + kC1, d2 = sxx + syy + kC2;
        const float s = (n1 * n2) / (d1 * d2);
        // Partials of s in μx, σx², σxy, then through σx² = E[x²] − μx², σxy = E[xy] − μxμy.
        const float ds_dmux = 2 * muy * n2 / (d1 * d2) - s * 2 * mux / d1;
        const float ds_dsxx = -s / d2;
        const float ds_dsxy = 2 * n1 / (d1 * d2);
        s_out[qx] = s;
        dmx[qx] = g * (ds_dmux - 2 * mux * ds_dsxx - muy * ds_dsxy);
        dexx[qx] = g * ds_dsxx;
        dexy[qx] = g * ds_dsxy;
      }
      if (!keep) continue;
      const float* keep_row = keep + size_t(qy + kHalf) * w + kHalf;
      for (int qx = 0; qx < ow; ++qx)
        if (keep_row[qx] == 0) s_out[qx] = dmx[qx] = dexx[qx] = dexy[qx] = 0.0f;
    }
    // Summed in position order on one thread: the same value whatever the thread count
    // (an ignored position adds 0, which leaves the sum's bits alone).
    double channel_sum = 0;
    for (size_t q = 0; q < n_out; ++q) channel_sum += b.s[q];
    total += channel_sum;
    if (!d_x) continue;
    filter_valid_transposed(b.dmx.data(), w, h, b.tmp.data(), b.gmx.data());
    filter_valid_transposed(b.dexx.data(), w, h, b.tmp.data(), b.gxx.data());
    filter_valid_transposed(b.dexy.data(), w, h, b.tmp.data(), b.gxy.data());
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < n_in; ++p) {
      const float dx = b.gmx[p] + 2 * b.px[p] * b.gxx[p] + b.py[p] * b.gxy[p];
      d_x[3 * p + ch] += keep ? keep[p] * dx : dx;
    }
  }
  return total / count;
}

}  // namespace

namespace {

void check_keep(std::span<const float> keep, size_t pixels) {
  if (!keep.empty() && keep.size() != pixels)
    throw std::invalid_argument("loss: the mask of kept pixels has " + std::to_string(keep.size()) +
                                " values for " + std::to_string(pixels) + " pixels");
}

}  // namespace

PhotometricLoss photometric_loss(std::span<const float> render, std::span<const float> target, int width,
                                 int height, float ssim_lambda, std::span<float> d_render,
                                 std::span<const float> keep) {
  check_sizes(render.size(), target.size(), width, height);
  check_keep(keep, render.size() / 3);
  const bool grad = !d_render.empty();
  if (grad && d_render.size() != render.size()) throw std::invalid_argument("loss: gradient buffer has the wrong size");
  double n = double(render.size());
  if (!keep.empty()) {
    n = 0;
    for (float k : keep) n += 3 * double(k);
  }
  const float l1_scale = n > 0 ? float((1.0 - ssim_lambda) / n) : 0.0f;
  // An ignored pixel's difference counts as 0: no L1, no gradient.
  auto diff_at = [&](size_t i) { return keep.empty() ? render[i] - target[i] : keep[i / 3] * (render[i] - target[i]); };
  if (grad) {
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < render.size(); ++i) {
      const float diff = diff_at(i);
      d_render[i] = diff > 0 ? l1_scale : (diff < 0 ? -l1_scale : 0.0f);
    }
  }
  double l1 = 0;  // the reported value: one sum in pixel order
  for (size_t i = 0; i < render.size(); ++i) l1 += std::abs(diff_at(i));
  l1 = n > 0 ? l1 / n : 0.0;
  // loss contains −λ·SSIM, so SSIM's gradient enters with scale −λ.
  const double s = ssim_and_gradient(render, target, width, height, -ssim_lambda, grad ? d_render.data() : nullptr,
                                     keep.empty() ? nullptr : keep.data());
  return {(1.0 - ssim_lambda) * l1 + ssim_lambda * (1.0 - s), l1, s};
}

double ssim(std::span<const float> a, std::span<const float> b, int width, int height, std::span<const float> keep) {
  check_sizes(a.size(), b.size(), width, height);
  check_keep(keep, a.size() / 3);
  return ssim_and_gradient(a, b, width, height, 0.0f, nullptr, keep.empty() ? nullptr : keep.data());
}

double psnr(std::span<const float> a, std::span<const float> b, std::span<const float> keep) {
  if (a.size() != b.size() || a.empty()) throw std::invalid_argument("psnr: image sizes differ or are empty");
  if (a.size() % 3 != 0) throw std::invalid_argument("psnr: the images are not RGB (3 floats per pixel)");
  check_keep(keep, a.size() / 3);
  double mse = 0, n = 0;
  for (size_t p = 0; p < a.size() / 3; ++p) {
    const double k = keep.empty() ? 1.0 : keep[p];
    for (size_t i = 3 * p; i < 3 * p + 3; ++i) {
      mse += k * double(a[i] - b[i]) * (a[i] - b[i]);
      n += k;
    }
  }
  if (n == 0) return INFINITY;  // nothing kept: nothing differs
  mse /= n;
  return mse > 0 ? -10.0 * std::log10(mse) : INFINITY;
}

}  // namespace desplat
