// Exposure, white balance and sensor noise.
#include "synth/photo_effects.hpp"

#include <algorithm>
#include <cmath>

#include "synth/random.hpp"

namespace desplat::synth {

std::array<double, 3> exposure_gain(const ExposureSpec& spec, uint64_t seed, int view) {
  Rng rng(seed, Stream::Exposure, static_cast<uint64_t>(view));
  const double gain = std::exp2(rng.uniform(-spec.stops, spec.stops));
  std::array<double, 3> out{};
  for (double& g : out) g = gain * (1 + rng.uniform(-spec.white_balance, spec.white_balance));
  return out;
}

void apply_gain(FloatImage& image, const std::array<double, 3>& gain) {
  for (size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = static_cast<float>(image.pixels[i] * gain[i % 3]);
}

void add_sensor_noise(FloatImage& image, const NoiseSpec& spec, uint64_t seed, int view) {
  const size_t row = static_cast<size_t>(image.width) * image.channels;
#pragma omp parallel for schedule(static)
  for (int j = 0; j < image.height; ++j) {
    Rng rng(seed, Stream::Noise, static_cast<uint64_t>(view), static_cast<uint64_t>(j));
    float* px = image.pixels.data() + static_cast<size_t>(j) * row;
    for (size_t i = 0; i < row; ++i) {
      const double variance = spec.sigma * spec.sigma + spec.shot * std::max(0.0f, px[i]);
      px[i] = static_cast<float>(px[i] + std::sqrt(variance) * rng.normal());
    }
  }
}

}  // namespace desplat::synth
