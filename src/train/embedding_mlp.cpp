// Initialization shared by the per-image models (embedding_mlp.hpp).
#include "desplat/train/embedding_mlp.hpp"

#include <cmath>

namespace desplat {

size_t mlp_weight_count(const std::vector<int>& s) {
  size_t n = 0;
  for (size_t l = 0; l + 1 < s.size(); ++l) n += size_t(s[l + 1]) * size_t(s[l] + 1);
  return n;
}

std::vector<float> initial_mlp_weights(const std::vector<int>& sizes, std::mt19937_64& rng) {
  std::vector<float> w;
  w.reserve(mlp_weight_count(sizes));
  for (size_t l = 0; l + 1 < sizes.size(); ++l) {
    const int in = sizes[l], out = sizes[l + 1];
    const bool last = l + 2 == sizes.size();
    std::uniform_real_distribution<float> u(-1.0f / std::sqrt(float(in)), 1.0f / std::sqrt(float(in)));
    for (int k = 0; k < out * (in + 1); ++k) w.push_back(last ? 0.0f : u(rng));
  }
  return w;
}

std::vector<float> initial_embeddings(size_t count, std::mt19937_64& rng) {
  std::normal_distribution<float> normal(0.0f, 0.01f);
  std::vector<float> e(count);
  for (float& x : e) x = normal(rng);
  return e;
}

}  // namespace desplat
