// Initial Gaussians (docs/METHOD.md §5), in whatever frame the points are given.
#pragma once

#include <array>
#include <cstdint>
#include <random>
#include <vector>

#include "desplat/core/gaussians.hpp"

namespace desplat {

// One static Gaussian per point: log-scale = log(mean distance to the 3 nearest
// neighbours) on all axes, uniformly random unit quaternion, opacity 0.1, SH DC from
// the point color ((rgb − 0.5) / Y₀), higher bands zero. `sh_degree` sets the stored
// degree. Deterministic for a seed.
GaussianSet init_gaussians_from_points(const std::vector<std::array<float, 3>>& xyz,
                                       const std::vector<std::array<uint8_t, 3>>& rgb, int sh_degree, uint64_t seed);

// Mean distance from each point to its k nearest other points (k-d tree, nanoflann).
std::vector<float> mean_knn_distance(const std::vector<std::array<float, 3>>& xyz, int k);

// A uniformly random unit quaternion (w, x, y, z): a normalized 4D standard normal sample.
// Draws from `normal` (mean 0, σ 1), so callers keep one random stream.
std::array<float, 4> random_unit_quaternion(std::mt19937_64& rng, std::normal_distribution<float>& normal);

}  // namespace desplat
