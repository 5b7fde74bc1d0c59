// Photometric loss of docs/METHOD.md §4 and the image metrics used for evaluation.
//
// Images are row-major [H, W, 3] floats (values nominally in [0, 1]). SSIM uses an
// 11×11 Gaussian window (σ = 1.5), K1 = 0.01, K2 = 0.03, data range 1, and only the
// "valid" window positions (no padding); it is the mean over those positions and the
// three channels. Images must be at least 11×11.
#pragma once

#include <span>

namespace desplat {

// The SSIM window's side [px]: the smallest image the loss and ssim() accept.
inline constexpr int kSsimWindow = 11;

struct PhotometricLoss {
  double loss = 0;  // (1 − λ)·L1 + λ·(1 − SSIM)
  double l1 = 0;    // mean |render − target|
  double ssim = 0;
};

// Loss and, when `d_render` is non-empty, its gradient ∂loss/∂render ([H, W, 3],
// overwritten). λ = ssim_lambda (0.2 in Splatfacto). Throws std::invalid_argument for
// mismatched sizes or images smaller than the SSIM window.
//
// `keep` (optional, [H, W], each 0 or 1): the user's mask of pixels to use. An ignored pixel
// (0) has no influence on the loss and gets zero gradient: L1 is the mean over kept pixels;
// SSIM sees both images multiplied by `keep` (so an ignored pixel reads 0 in both, whatever
// the photo holds there) and averages over the window positions whose center is kept. With
// nothing kept the loss is 0. An empty `keep` is the unmasked loss, bit for bit.
PhotometricLoss photometric_loss(std::span<const float> render, std::span<const float> target, int width, int height,
                                 float ssim_lambda, std::span<float> d_render, std::span<const float> keep = {});

// Both metrics take the same optional `keep` mask: ignored pixels leave the comparison
// (SSIM as in photometric_loss; PSNR over kept pixels; +inf when nothing is kept).
double ssim(std::span<const float> a, std::span<const float> b, int width, int height,
            std::span<const float> keep = {});
// Peak signal-to-noise ratio for data range 1: −10·log10(mean squared error).
double psnr(std::span<const float> a, std::span<const float> b, std::span<const float> keep = {});

}  // namespace desplat
