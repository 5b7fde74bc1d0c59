// Exact gradients of L = Σ wC·C + Σ wA·A + Σ wD·D through the brute-force reference,
// by forward-mode automatic differentiation with ceres::Jet (double precision).
#pragma once

#include <ceres/jet.h>

#include <vector>

#include "desplat/train/param_groups.hpp"
#include "support/reference_render.hpp"

namespace desplat::test {

// Parameters flattened group by group, in the parameter-group table's order.
inline std::vector<float> flatten_params(const GaussianSet& g) {
  std::vector<float> p;
  for (const ParamGroupInfo& info : kParamGroupTable)
    p.insert(p.end(), (g.*info.values).begin(), (g.*info.values).end());
  return p;
}

inline std::vector<float> flatten_grads(const RasterGradients& gr) {
  std::vector<float> p;
  for (const ParamGroupInfo& info : kParamGroupTable)
    p.insert(p.end(), (gr.*info.grads).begin(), (gr.*info.grads).end());
  return p;
}

template <typename T>
T weighted_loss(const RefImage<T>& img, const std::vector<float>& wC, const std::vector<float>& wA,
                const std::vector<float>& wD) {
  T L(0);
  for (size_t i = 0; i < img.color.size(); ++i) L += img.color[i] * double(wC[i]);
  for (size_t i = 0; i < img.alpha.size(); ++i) L += img.alpha[i] * double(wA[i]);
  for (size_t i = 0; i < img.depth.size(); ++i) L += img.depth[i] * double(wD[i]);
  return L;
}

inline std::vector<double> jet_gradient(const GaussianSet& g, const Camera& cam, const RasterSettings& s,
                                        const std::vector<float>& wC, const std::vector<float>& wA,
                                        const std::vector<float>& wD) {
  constexpr int kChunk = 8;
  using J = ceres::Jet<double, kChunk>;
  const std::vector<float> flat = flatten_params(g);
  std::vector<double> grad(flat.size(), 0.0);
  for (size_t start = 0; start < flat.size(); start += kChunk) {
    std::vector<J> values(flat.size());
    for (size_t i = 0; i < flat.size(); ++i) values[i] = J(flat[i]);
    for (int k = 0; k < kChunk && start + k < flat.size(); ++k) values[start + k].v[k] = 1.0;
    RefGaussians<J> r;
    r.color_mode = g.color_mode;
    r.sh_degree = g.sh_degree;
    size_t at = 0;
    for (const ParamGroupInfo& info : kParamGroupTable) {
      const size_t n = (g.*info.values).size();
      r.array(info.id).assign(values.begin() + at, values.begin() + at + n);
      at += n;
    }
    const J L = weighted_loss(reference_render<J>(r, cam, s), wC, wA, wD);
    for (int k = 0; k < kChunk && start + k < flat.size(); ++k) grad[start + k] = L.v[k];
  }
  return grad;
}

}  // namespace desplat::test
