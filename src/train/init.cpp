// Initialization of static Gaussians from a point cloud (docs/METHOD.md §5).
#include "desplat/train/init.hpp"

#include <nanoflann.hpp>

#include <cmath>
#include <random>
#include <stdexcept>

#include "desplat/core/spherical_harmonics.hpp"

namespace desplat {
namespace {

struct PointCloudAdaptor {
  const std::vector<std::array<float, 3>>& pts;
  size_t kdtree_get_point_count() const { return pts.size(); }
  float kdtree_get_pt(size_t i, size_t dim) const { return pts[i][dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointCloudAdaptor>,
                                                   PointCloudAdaptor, 3, uint32_t>;

}  // namespace

std::vector<float> mean_knn_distance(const std::vector<std::array<float, 3>>& xyz, int k) {
  std::vector<float> out(xyz.size(), 0.0f);
  if (xyz.size() < 2) return out;
  const PointCloudAdaptor adaptor{xyz};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const size_t want = std::min<size_t>(k + 1, xyz.size());  // the point itself comes back first
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < static_cast<int64_t>(xyz.size()); ++i) {
    uint32_t idx[16];
    float dist2[16];
    const size_t found = tree.knnSearch(xyz[i].data(), want, idx, dist2);
    double sum = 0;
    int used = 0;
    for (size_t j = 0; j < found; ++j) {
      if (idx[j] == static_cast<uint32_t>(i)) continue;
      sum += std::sqrt(double(dist2[j]));
      if (++used == k) break;
    }
    out[i] = used > 0 ? static_cast<float>(sum / used) : 0.0f;
  }
  return out;
}

GaussianSet init_gaussians_from_points(const std::vector<std::array<float, 3>>& xyz,
                                       const std::vector<std::array<uint8_t, 3>>& rgb, int sh_degree, uint64_t seed) {
  if (xyz.size() != rgb.size()) throw std::invalid_argument("init: point and color counts differ");
  if (sh_degree < 0 || sh_degree > 3) throw std::invalid_argument("init: SH degree must be 0..3");
  GaussianSet g;
  g.sh_degree = sh_degree;
  g.resize(xyz.size());
  const std::vector<float> dist = mean_knn_distance(xyz, 3);
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const int stride = 3 * sh_coeff_count(sh_degree);
  const float opacity_logit = std::log(0.1f / 0.9f);
  for (size_t i = 0; i < xyz.size(); ++i) {
    // Coincident points have zero neighbour distance; keep the log finite.
    const float log_scale = std::log(std::max(dist[i], 1e-7f));
    const std::array<float, 4> q = random_unit_quaternion(rng, normal);
    for (int k = 0; k < 3; ++k) g.means[3 * i + k] = xyz[i][k], g.log_scales[3 * i + k] = log_scale;
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = q[k];
    g.opacity_logits[i] = opacity_logit;
    for (int c = 0; c < 3; ++c) g.colors[stride * i + c] = (rgb[i][c] / 255.0f - 0.5f) / float(kShBand0);
  }
  return g;
}

std::array<float, 4> random_unit_quaternion(std::mt19937_64& rng, std::normal_distribution<float>& normal) {
  std::array<float, 4> q;
  float n2 = 0;
  do {
    n2 = 0;
    for (float& v : q) v = normal(rng), n2 += v * v;
  } while (n2 < 1e-12f);
  const float norm = std::sqrt(n2);
  for (float& v : q) v /= norm;
  return q;
}

}  // namespace desplat
