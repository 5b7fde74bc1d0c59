// What the camera does to a view after the light arrives: a per-view exposure and white
// balance (one gain per channel) and sensor noise. Both are deterministic in (seed, view).
#pragma once

#include <array>
#include <cstdint>

#include "desplat/io/image_io.hpp"
#include "desplat/synth/synth.hpp"

namespace desplat::synth {

// Per-channel gain 2^u · (1 + w_c), u ~ U[−stops, stops], w_c ~ U[−white_balance, white_balance].
std::array<double, 3> exposure_gain(const ExposureSpec& spec, uint64_t seed, int view);
void apply_gain(FloatImage& image, const std::array<double, 3>& gain);

// Adds N(0, sigma² + shot·max(value, 0)) to every channel of every pixel (values may leave
// [0, 1]; the PNG writer clamps). One random stream per row: independent of thread count.
void add_sensor_noise(FloatImage& image, const NoiseSpec& spec, uint64_t seed, int view);

}  // namespace desplat::synth
