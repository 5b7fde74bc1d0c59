// Camera paths compared up to a similarity: the least-squares similarity between two point sets
// (Umeyama 1991) and the relative error left after it, for tests that check an SfM model against
// known camera centres.
#pragma once

#include <Eigen/Dense>
#include <cmath>

namespace desplat::testing {

struct Similarity {
  double scale = 1;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Vector3d operator()(const Eigen::Vector3d& p) const { return scale * rotation * p + translation; }
};

// Least-squares similarity taking `from` onto `to` (Umeyama 1991), with fixed-size 3×3 algebra.
inline Similarity umeyama(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to) {
  const Eigen::Index n = from.cols();
  const Eigen::Vector3d mf = from.rowwise().mean(), mt = to.rowwise().mean();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var_from = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d f = from.col(i) - mf, t = to.col(i) - mt;
    cov += t * f.transpose();
    var_from += f.squaredNorm();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s = Eigen::Vector3d::Ones();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) s(2) = -1;  // no reflection
  Similarity sim;
  sim.rotation = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  sim.scale = svd.singularValues().dot(s) / var_from;
  sim.translation = mt - sim.scale * sim.rotation * mf;
  return sim;
}

// RMS distance of the aligned centers over the RMS spread of the reference centers.
inline double relative_alignment_error(const Eigen::Matrix3Xd& ours, const Eigen::Matrix3Xd& ref) {
  const Similarity sim = umeyama(ours, ref);
  const Eigen::Vector3d mean = ref.rowwise().mean();
  double residual = 0, spread = 0;
  for (Eigen::Index i = 0; i < ours.cols(); ++i) {
    residual += (sim(ours.col(i)) - ref.col(i)).squaredNorm();
    spread += (ref.col(i) - mean).squaredNorm();
  }
  return std::sqrt(residual / spread);
}

}  // namespace desplat::testing
