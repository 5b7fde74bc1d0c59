// What the per-image models (appearance §10, background §11 of docs/METHOD.md) share: an MLP
// stored flat — layer l's weights row-major [out_l, in_l], then its bias [out_l] — and a table
// of per-image embeddings, initialized the same way.
#pragma once

#include <cstddef>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace desplat {

// The number of floats of an MLP with these layer sizes (input, hidden…, output).
size_t mlp_weight_count(const std::vector<int>& sizes);

// PyTorch's default for the hidden layers, U(±1/√in) for weights and biases, and zero for the
// last layer: a new model's outputs are 0 whatever its input. Draws from `rng` in storage order.
std::vector<float> initial_mlp_weights(const std::vector<int>& sizes, std::mt19937_64& rng);

// `count` embedding values N(0, 0.01²), drawn from `rng` in order.
std::vector<float> initial_embeddings(size_t count, std::mt19937_64& rng);

// Throws std::logic_error naming `what` when a per-image model's arrays (mlp, image_embeddings
// and their Adam moments mlp_m/mlp_v, embed_m/embed_v) disagree with its settings.
template <class Model>
void check_per_image_model(const Model& m, const std::string& what) {
  if (m.mlp.size() != m.mlp_floats() || m.mlp_m.size() != m.mlp.size() || m.mlp_v.size() != m.mlp.size())
    throw std::logic_error(what + " MLP weights do not match its settings");
  const size_t n = m.image_embeddings.size();
  if (n % size_t(m.settings.image_dim) != 0 || m.embed_m.size() != n || m.embed_v.size() != n)
    throw std::logic_error(what + " image embeddings do not match image_dim");
}

}  // namespace desplat
