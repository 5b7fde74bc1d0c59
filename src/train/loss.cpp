// 0.8·L1 + 0.2·(1 − SSIM) with a hand-written gradient. SSIM's five local statistics
// come from a separable 11-tap Gaussian filter over the valid region; the gradient
// goes back through the same filter transposed (a "full" scatter).
#include "desplat/train/loss.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <omp.h>

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

void check_sizes(size_t a, size_t b, int width, int height) {
  if (width < kWindow || height < kWindow)
    throw std::invalid_argument("SSIM needs images of at least 11x11 pixels, got " + std::to_string(width) + "x" +
                                std::to_string(height));
  if (a != size_t(width) * height * 3 || b != a)
    throw std::invalid_argument("loss: image buffers do not match " + std::to_string(width) + "x" +
                                std::to_string(height) + "x3");
}

// One thread's rows of the fused SSIM below, kept between calls so a training step
// allocates nothing once the image size is known.
struct SsimRows {
  std::vector<float> products;  // [5][w]: x, y, x², y², xy of one input row (masked)
  std::vector<float> ring;      // [11][5][ow]: the last 11 rows filtered horizontally
  std::vector<float> stats;     // [5][ow]: μx, μy, E[x²], E[y²], E[xy] of one position row
  std::vector<float> s_row;     // [ow]: s along that row (0 where the centre is ignored)
  std::vector<float> back;      // [3][10 + ow + 10]: one row of the partials filtered back vertically
  std::vector<float> grad;      // [3][w]: … and horizontally: ∂/∂μx, ∂/∂E[x²], ∂/∂E[xy] per pixel
  std::vector<float> ones;      // [w]: the mask row when there is no mask
};

// What the threads share: the partials of s per position, which the backward reads across
// the threads' bands, and each position row's sum of s.
struct SsimShared {
  std::vector<float> partials;   // [3 channels][3][oh][ow]: g·∂s/∂μx, g·∂s/∂E[x²], g·∂s/∂E[xy]
  std::vector<double> row_sums;  // [3 channels][oh]: Σ s along the row
};

// Mean SSIM over valid positions and channels; when d_x is given, adds
// scale·∂SSIM/∂x to it ([H, W, 3]).
// With `keep` ([H, W] in {0, 1}) both images are multiplied by it first, so an ignored pixel
// reads 0 in both whatever it holds, and the mean runs over the positions whose window center
// is kept: an ignored pixel has no influence on the value and gets no gradient.
//
// Fused row by row: each thread takes a band of position rows and slides down it, filtering
// each input row horizontally into a ring of the last 11 and each position row vertically
// from that ring, so the five statistics never exist as whole images (as whole images they
// would be 15 planes a step, each written and read again). Every value is
// the same sum in the same order as the separable filters give, whatever the band, so the
// result does not depend on the thread count. One barrier: the backward's vertical pass reads
// the partials of up to 10 position rows above its own band.
double ssim_and_gradient(std::span<const float> x, std::span<const float> y, int w, int h, float scale, float* d_x,
                         const float* keep = nullptr) {
  const int ow = w - kWindow + 1, oh = h - kWindow + 1;
  const size_t n_out = size_t(ow) * oh;
  constexpr int kHalf = kWindow / 2;
  double kept_positions = double(n_out);
  if (keep) {
    kept_positions = 0;
    for (int qy = 0; qy < oh; ++qy)
      for (int qx = 0; qx < ow; ++qx) kept_positions += keep[size_t(qy + kHalf) * w + qx + kHalf];
    if (kept_positions == 0) return 1.0;  // nothing to compare: no loss, no gradient
  }
  const double count = kept_positions * 3;
  const float g = float(scale / count);
  thread_local SsimShared shared_scratch;
  SsimShared& shared = shared_scratch;  // the calling thread's; the team below shares it
  shared.row_sums.assign(size_t(3) * oh, 0.0);
  if (d_x) shared.partials.resize(9 * n_out);

#pragma omp parallel
  {
    thread_local SsimRows scratch;
    SsimRows& r = scratch;
    r.products.resize(size_t(5) * w);
    r.ring.resize(size_t(kWindow) * 5 * ow);
    r.stats.resize(size_t(5) * ow);
    r.s_row.resize(size_t(ow));
    r.ones.assign(size_t(w), 1.0f);
    // Without a mask every row reads a row of ones: ×1 leaves each value's bits alone, and the
    // vector loops then load from a real row (a masked-off load from a null pointer is
    // legal but, on AMD Zen, takes a slow assist every time).
    auto keep_row_of = [&](int row) { return keep ? keep + size_t(row) * w : r.ones.data(); };
    const int threads = omp_get_num_threads(), me = omp_get_thread_num();
    const int q_begin = int(int64_t(oh) * me / threads), q_end = int(int64_t(oh) * (me + 1) / threads);
    auto ring_row = [&](int input_row, int plane) { return &r.ring[(size_t(input_row % kWindow) * 5 + plane) * ow]; };

    for (int ch = 0; ch < 3 && q_begin < q_end; ++ch) {
      for (int in_row = q_begin; in_row < q_end + kWindow - 1; ++in_row) {
        // The input row's five products, filtered horizontally into the ring.
        const size_t p0 = size_t(in_row) * w;
        float *px = &r.products[0], *py = px + w, *pxx = py + w, *pyy = pxx + w, *pxy = pyy + w;
        const float* keep_in = keep_row_of(in_row);
#pragma omp simd
        for (int i = 0; i < w; ++i) {
          const float k = keep_in[i];
          const float xv = k * x[3 * (p0 + i) + ch], yv = k * y[3 * (p0 + i) + ch];
          px[i] = xv, py[i] = yv;
          pxx[i] = xv * xv, pyy[i] = yv * yv, pxy[i] = xv * yv;
        }
        for (int plane = 0; plane < 5; ++plane) {
          const float* row = &r.products[size_t(plane) * w];
          const float* taps[kWindow];
          for (int k = 0; k < kWindow; ++k) taps[k] = row + k;
          weighted_sum_of_rows(taps, kGauss.w, kWindow, ow, ring_row(in_row, plane));
        }
        const int qy = in_row - (kWindow - 1);  // the position row whose window this row completes
        if (qy < q_begin) continue;
        for (int plane = 0; plane < 5; ++plane) {
          const float* taps[kWindow];
          for (int k = 0; k < kWindow; ++k) taps[k] = ring_row(qy + k, plane);
          weighted_sum_of_rows(taps, kGauss.w, kWindow, ow, &r.stats[size_t(plane) * ow]);
        }
        // The per-position SSIM and its partials; an ignored centre gets s = 0 and no gradient.
        const float *mx = &r.stats[0], *my = mx + ow, *exx = my + ow, *eyy = exx + ow, *exy = eyy + ow;
        float* dmx = d_x ? &shared.partials[(size_t(3 * ch) * oh + qy) * ow] : nullptr;
        float* dexx = d_x ? dmx + n_out : nullptr;
        float* dexy = d_x ? dexx + n_out : nullptr;
        const float* keep_row = keep_row_of(qy + kHalf) + kHalf;
        float* s_row = &r.s_row[0];
#pragma omp simd
        for (int qx = 0; qx < ow; ++qx) {
          const float mux = mx[qx], muy = my[qx];
          const float sxx = exx[qx] - mux * mux, syy = eyy[qx] - muy * muy, sxy = exy[qx] - mux * muy;
          const float n1 = 2 * mux * muy + kC1, n2 = 2 * sxy + kC2;
          const float d1 = mux * mux + muy * muy + kC1, d2 = sxx + syy + kC2;
          const float s = (n1 * n2) / (d1 * d2);
          const bool kept = keep_row[qx] != 0;
          s_row[qx] = kept ? s : 0.0f;
          if (dmx) {
            // Partials of s in μx, σx², σxy, then through σx² = E[x²] − μx², σxy = E[xy] − μxμy.
            const float ds_dmux = 2 * muy * n2 / (d1 * d2) - s * 2 * mux / d1;
            const float ds_dsxx = -s / d2;
            const float ds_dsxy = 2 * n1 / (d1 * d2);
            dmx[qx] = kept ? g * (ds_dmux - 2 * mux * ds_dsxx - muy * ds_dsxy) : 0.0f;
            dexx[qx] = kept ? g * ds_dsxx : 0.0f;
            dexy[qx] = kept ? g * ds_dsxy : 0.0f;
          }
        }
        // Each row's sum is one fixed computation (vector lanes, then the lanes), so the
        // value does not depend on the thread count.
        double row_sum = 0;
#pragma omp simd reduction(+ : row_sum)
        for (int qx = 0; qx < ow; ++qx) row_sum += s_row[qx];
        shared.row_sums[size_t(ch) * oh + qy] = row_sum;
      }
    }

    if (d_x) {
#pragma omp barrier
      const int padded_ow = ow + 2 * (kWindow - 1);
      r.back.assign(size_t(3) * padded_ow, 0.0f);
      r.grad.resize(size_t(3) * w);
      float reversed[kWindow];  // reversed[i] = w[10 − i]: the taps in source order
      for (int i = 0; i < kWindow; ++i) reversed[i] = kGauss.w[kWindow - 1 - i];
      const int y_begin = int(int64_t(h) * me / threads), y_end = int(int64_t(h) * (me + 1) / threads);
      for (int ch = 0; ch < 3; ++ch)
        for (int Y = y_begin; Y < y_end; ++Y) {
          // Vertical: back[Y] = Σ_{qy = Y−k valid} w[k]·partial[qy], position rows ascending.
          const int k_hi = std::min(kWindow - 1, Y), k_lo = std::max(0, Y - (oh - 1));
          for (int plane = 0; plane < 3; ++plane) {
            const float* src = &shared.partials[size_t(3 * ch + plane) * n_out];
            const float* taps[kWindow];
            for (int k = k_hi; k >= k_lo; --k) taps[k_hi - k] = src + size_t(Y - k) * ow;
            weighted_sum_of_rows(taps, reversed + (kWindow - 1 - k_hi), k_hi - k_lo + 1, ow,
                                 &r.back[size_t(plane) * padded_ow + kWindow - 1]);
          }
          // Horizontal: grad[X] = Σ_{x = X−k valid} w[k]·back[x], sources x ascending (k
          // descending), each sum started at +0: blocked sums over 11 shifted rows. The row has
          // 10 zeros on each side, so a column near an edge adds zeros for the sources it
          // lacks; a sum that started at +0 is never −0, and adding +0 leaves its bits alone.
          for (int plane = 0; plane < 3; ++plane) {
            const float* padded = &r.back[size_t(plane) * padded_ow];
            const float* taps[kWindow];
            for (int i = 0; i < kWindow; ++i) taps[i] = padded + i;  // column X reads back[X − 10 + i]
            weighted_sum_of_rows(taps, reversed, kWindow, w, &r.grad[size_t(plane) * w]);
          }
          const size_t p0 = size_t(Y) * w;
          const float *gmx = &r.grad[0], *gxx = gmx + w, *gxy = gxx + w;
          const float* keep_in = keep_row_of(Y);
#pragma omp simd
          for (int i = 0; i < w; ++i) {
            const float k = keep_in[i];
            const float xv = k * x[3 * (p0 + i) + ch], yv = k * y[3 * (p0 + i) + ch];
            const float dx = gmx[i] + 2 * xv * gxx[i] + yv * gxy[i];
            d_x[3 * (p0 + i) + ch] += k * dx;
          }
        }
    }
  }
  double total = 0;
  for (int ch = 0; ch < 3; ++ch) {
    double channel_sum = 0;  // the rows in order: the same value whatever the thread count
    for (int qy = 0; qy < oh; ++qy) channel_sum += shared.row_sums[size_t(ch) * oh + qy];
    total += channel_sum;
  }
  return total / count;
}

}  // namespace

namespace {

void check_keep(std::span<const float> keep, size_t pixels) {
  if (!keep.empty() && keep.size() != pixels)
    throw std::invalid_argument("loss: the mask of kept pixels has " + std::to_string(keep.size()) + " values for " +
                                std::to_string(pixels) + " pixels");
}

}  // namespace

PhotometricLoss photometric_loss(std::span<const float> render, std::span<const float> target, int width, int height,
                                 float ssim_lambda, std::span<float> d_render, std::span<const float> keep) {
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
  // An ignored pixel's difference counts as 0: no L1, no gradient. One pass per image row
  // writes the gradient's L1 part and sums the row; the rows are then added in order, so the
  // value does not depend on the thread count.
  thread_local std::vector<double> row_l1_scratch;
  std::vector<double>& row_l1 = row_l1_scratch;  // the calling thread's; the team below shares it
  row_l1.assign(size_t(height), 0.0);
#pragma omp parallel for schedule(static)
  for (int row = 0; row < height; ++row) {
    const size_t p0 = size_t(row) * width;
    double sum = 0;
    // Compile-time variants, so each is one branch-free vector loop (the signs of the
    // differences are random: a branch on them is mispredicted half the time).
    auto row_pass = [&](auto masked, auto with_grad) {
      const float* r = render.data() + 3 * p0;
      const float* t = target.data() + 3 * p0;
      const float* k = masked ? keep.data() + p0 : nullptr;
      float* d = with_grad ? d_render.data() + 3 * p0 : nullptr;
      const float step = l1_scale;  // a local: read through the capture, it blocked vectorization
#pragma omp simd reduction(+ : sum)
      for (int i = 0; i < 3 * width; ++i) {
        const float diff = masked ? k[i / 3] * (r[i] - t[i]) : r[i] - t[i];
        if (with_grad) d[i] = diff > 0 ? step : (diff < 0 ? -step : 0.0f);
        sum += std::abs(diff);
      }
    };
    if (keep.empty())
      grad ? row_pass(std::false_type{}, std::true_type{}) : row_pass(std::false_type{}, std::false_type{});
    else
      grad ? row_pass(std::true_type{}, std::true_type{}) : row_pass(std::true_type{}, std::false_type{});
    row_l1[size_t(row)] = sum;
  }
  double l1 = 0;
  for (double row_sum : row_l1) l1 += row_sum;
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
  // Fixed chunks of pixels, summed on the threads and then in chunk order: the value does
  // not depend on the thread count.
  constexpr int64_t kChunk = 4096;
  const int64_t pixels = int64_t(a.size() / 3), chunks = (pixels + kChunk - 1) / kChunk;
  thread_local std::vector<double> se_scratch, n_scratch;  // reused: no allocation per step
  std::vector<double>& chunk_se = se_scratch;              // the calling thread's; the team below shares them
  std::vector<double>& chunk_n = n_scratch;
  chunk_se.assign(static_cast<size_t>(chunks), 0.0);
  chunk_n.assign(static_cast<size_t>(chunks), 0.0);
#pragma omp parallel for schedule(static)
  for (int64_t c = 0; c < chunks; ++c) {
    double se = 0, kept = 0;
    for (int64_t p = c * kChunk; p < std::min(pixels, (c + 1) * kChunk); ++p) {
      const double k = keep.empty() ? 1.0 : keep[size_t(p)];
      for (size_t i = 3 * size_t(p); i < 3 * size_t(p) + 3; ++i) {
        se += k * double(a[i] - b[i]) * (a[i] - b[i]);
        kept += k;
      }
    }
    chunk_se[size_t(c)] = se, chunk_n[size_t(c)] = kept;
  }
  double mse = 0, n = 0;
  for (int64_t c = 0; c < chunks; ++c) mse += chunk_se[size_t(c)], n += chunk_n[size_t(c)];
  if (n == 0) return INFINITY;  // nothing kept: nothing differs
  mse /= n;
  return mse > 0 ? -10.0 * std::log10(mse) : INFINITY;
}

}  // namespace desplat
