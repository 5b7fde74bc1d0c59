// The relative motion of colmap's verified pairs and the capture evidence it gives; see
// src/sfm/two_view_evidence.hpp.
#include "sfm/two_view_evidence.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include "desplat/core/statistics.hpp"
#include "desplat/io/camera_models.hpp"
#include "desplat/io/colmap.hpp"
#include "sfm/colmap_database.hpp"

namespace desplat::sfm {
namespace {

constexpr double kDeg = 180 / std::numbers::pi;

// The correspondences a pair's motion is judged from: at most this many, evenly spaced over its
// inliers (the median angle and the vote between decompositions settle long before).
constexpr size_t kMaxPointsPerPair = 400;

// The point both rays meet nearest (linear triangulation), camera 1 at the origin.
Eigen::Vector3d triangulate(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const Eigen::Vector2d& x1,
                            const Eigen::Vector2d& x2) {
  Eigen::Matrix<double, 3, 4> P1 = Eigen::Matrix<double, 3, 4>::Zero(), P2;
  P1.leftCols<3>().setIdentity();
  P2 << R, t;
  Eigen::Matrix4d A;
  A.row(0) = x1.x() * P1.row(2) - P1.row(0);
  A.row(1) = x1.y() * P1.row(2) - P1.row(1);
  A.row(2) = x2.x() * P2.row(2) - P2.row(0);
  A.row(3) = x2.y() * P2.row(2) - P2.row(1);
  const Eigen::Vector4d X = Eigen::JacobiSVD<Eigen::Matrix4d>(A, Eigen::ComputeFullV).matrixV().col(3);
  return X.head<3>() / X.w();
}

struct Candidate {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  std::vector<double> angles_deg;  // of the points in front of both cameras
};

Candidate evaluate(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const std::vector<Eigen::Vector2d>& x1,
                   const std::vector<Eigen::Vector2d>& x2) {
  Candidate c{R, t, {}};
  const Eigen::Vector3d center2 = -R.transpose() * t;
  for (size_t i = 0; i < x1.size(); ++i) {
    const Eigen::Vector3d X = triangulate(R, t, x1[i], x2[i]);
    if (!X.allFinite() || X.z() <= 0 || (R * X + t).z() <= 0) continue;
    const Eigen::Vector3d ray1 = X, ray2 = X - center2;
    const double cosine = ray1.dot(ray2) / (ray1.norm() * ray2.norm());
    c.angles_deg.push_back(std::acos(std::clamp(cosine, -1.0, 1.0)) * kDeg);
  }
  return c;
}

// A matrix colmap wrote as 9 doubles, row-major (it transposes Eigen's column-major storage
// before writing); nullopt for a missing, short or all-zero blob.
std::optional<Eigen::Matrix3d> matrix_blob(sqlite3_stmt* s, int column) {
  if (sqlite3_column_bytes(s, column) != 9 * static_cast<int>(sizeof(double))) return std::nullopt;
  double v[9];
  std::memcpy(v, sqlite3_column_blob(s, column), sizeof v);
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m(r, c) = v[3 * r + c];
  if (!m.allFinite() || m.isZero(0)) return std::nullopt;
  return m;
}

Eigen::Matrix3d intrinsic_matrix(const colmap::Camera& camera) {
  const PinholeIntrinsics k = pinhole_intrinsics(camera);
  Eigen::Matrix3d K;
  K << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1;
  return K;
}

// The database's camera rows as io's cameras; a row whose model or parameters do not fit is left
// out (its photos' pairs get no motion).
std::map<int, colmap::Camera> read_cameras(const ColmapDatabase& db) {
  std::map<int, colmap::Camera> cameras;
  db.query("SELECT camera_id, model, width, height, params FROM cameras", [&](sqlite3_stmt* s) {
    colmap::Camera cam;
    cam.id = static_cast<uint32_t>(sqlite3_column_int64(s, 0));
    const int model = sqlite3_column_int(s, 1);
    try {
      cam.model = static_cast<colmap::CameraModelId>(model);
      const int n = colmap::camera_model_info(cam.model).num_params;
      if (sqlite3_column_bytes(s, 4) != n * static_cast<int>(sizeof(double))) return;
      cam.params.resize(static_cast<size_t>(n));
      std::memcpy(cam.params.data(), sqlite3_column_blob(s, 4), cam.params.size() * sizeof(double));
    } catch (const std::exception&) {
      return;
    }
    cam.width = static_cast<uint64_t>(std::max<int64_t>(0, sqlite3_column_int64(s, 2)));
    cam.height = static_cast<uint64_t>(std::max<int64_t>(0, sqlite3_column_int64(s, 3)));
    if (pinhole_intrinsics(cam).fx > 0) cameras[static_cast<int>(cam.id)] = cam;
  });
  return cameras;
}

}  // namespace

std::optional<RelativeMotion> motion_from_essential(const Eigen::Matrix3d& E, const std::vector<Eigen::Vector2d>& x1,
                                                    const std::vector<Eigen::Vector2d>& x2) {
  if (x1.size() != x2.size() || x1.empty() || !E.allFinite() || E.isZero(0)) return std::nullopt;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  if (U.determinant() < 0) U = -U;
  if (V.determinant() < 0) V = -V;
  Eigen::Matrix3d W;
  W << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const Eigen::Vector3d t = U.col(2).normalized();
  std::optional<Candidate> best;
  for (const Eigen::Matrix3d& R :
       {Eigen::Matrix3d(U * W * V.transpose()), Eigen::Matrix3d(U * W.transpose() * V.transpose())})
    for (const Eigen::Vector3d& tt : {t, Eigen::Vector3d(-t)}) {
      Candidate c = evaluate(R, tt, x1, x2);
      if (!best || c.angles_deg.size() > best->angles_deg.size()) best = std::move(c);
    }
  if (!best || best->angles_deg.empty()) return std::nullopt;
  RelativeMotion m;
  m.R = best->R;
  m.t = best->t;
  m.points_in_front = static_cast<int>(best->angles_deg.size());
  m.forward = std::abs(best->t.z());
  m.median_tri_angle_deg = median(best->angles_deg);
  return m;
}

CaptureGeometry read_capture_geometry(const std::filesystem::path& database) {
  const ColmapDatabase db(database, SQLITE_OPEN_READONLY);
  CaptureGeometry g;
  const std::map<int, colmap::Camera> cameras = read_cameras(db);
  std::map<int, int> camera_of;
  db.query("SELECT image_id, name, camera_id FROM images", [&](sqlite3_stmt* s) {
    const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(s, 1));
    const int id = static_cast<int>(sqlite3_column_int64(s, 0));
    g.names[id] = text ? text : "";
    camera_of[id] = static_cast<int>(sqlite3_column_int64(s, 2));
  });
  // Keypoints: rows × cols float32, x and y first [px, colmap's convention: pixel centres at +0.5].
  std::map<int, std::vector<float>> xy;
  std::map<int, int> columns;
  db.query("SELECT image_id, rows, cols, data FROM keypoints", [&](sqlite3_stmt* s) {
    const int id = static_cast<int>(sqlite3_column_int64(s, 0));
    const int64_t rows = sqlite3_column_int64(s, 1), cols = sqlite3_column_int64(s, 2);
    if (rows <= 0 || cols < 2 || sqlite3_column_bytes(s, 3) != rows * cols * static_cast<int64_t>(sizeof(float)))
      return;
    std::vector<float>& v = xy[id];
    v.resize(static_cast<size_t>(rows * cols));
    std::memcpy(v.data(), sqlite3_column_blob(s, 3), v.size() * sizeof(float));
    columns[id] = static_cast<int>(cols);
  });
  db.query("SELECT pair_id, rows, cols, data, config, F, E FROM two_view_geometries WHERE rows > 0",
           [&](sqlite3_stmt* s) {
             PairGeometry p;
             const int64_t pair = sqlite3_column_int64(s, 0);
             p.image1 = static_cast<int>(pair / kColmapMaxImageId);
             p.image2 = static_cast<int>(pair % kColmapMaxImageId);
             p.inliers = sqlite3_column_int(s, 1);
             p.config = sqlite3_column_int(s, 4);
             g.pairs.push_back(p);
             const auto cam1 = cameras.find(camera_of.count(p.image1) ? camera_of[p.image1] : -1);
             const auto cam2 = cameras.find(camera_of.count(p.image2) ? camera_of[p.image2] : -1);
             const auto kp1 = xy.find(p.image1), kp2 = xy.find(p.image2);
             const int64_t rows = sqlite3_column_int64(s, 1);
             if (cam1 == cameras.end() || cam2 == cameras.end() || kp1 == xy.end() || kp2 == xy.end() ||
                 sqlite3_column_int64(s, 2) != 2 ||
                 sqlite3_column_bytes(s, 3) != rows * 2 * static_cast<int64_t>(sizeof(uint32_t)))
               return;
             // Calibrated pairs (EXIF focal length) carry E; the others F, made essential with
             // the intrinsics colmap's mapper starts from.
             std::optional<Eigen::Matrix3d> E = p.config == 2 ? matrix_blob(s, 6) : std::nullopt;
             if (!E) {
               const std::optional<Eigen::Matrix3d> F = matrix_blob(s, 5);
               if (!F) return;
               E = intrinsic_matrix(cam2->second).transpose() * *F * intrinsic_matrix(cam1->second);
             }
             std::vector<uint32_t> matches(static_cast<size_t>(rows * 2));
             std::memcpy(matches.data(), sqlite3_column_blob(s, 3), matches.size() * sizeof(uint32_t));
             const size_t stride = std::max<size_t>(1, static_cast<size_t>(rows) / kMaxPointsPerPair);
             const size_t n1 = kp1->second.size() / static_cast<size_t>(columns[p.image1]);
             const size_t n2 = kp2->second.size() / static_cast<size_t>(columns[p.image2]);
             std::vector<Eigen::Vector2d> x1, x2;
             for (size_t i = 0; i < static_cast<size_t>(rows); i += stride) {
               const size_t a = matches[2 * i], b = matches[2 * i + 1];
               if (a >= n1 || b >= n2) continue;
               const float* k1 = &kp1->second[a * static_cast<size_t>(columns[p.image1])];
               const float* k2 = &kp2->second[b * static_cast<size_t>(columns[p.image2])];
               const Vec2 u1 = camera_from_image(cam1->second, {k1[0], k1[1]});
               const Vec2 u2 = camera_from_image(cam2->second, {k2[0], k2[1]});
               x1.emplace_back(u1[0], u1[1]);
               x2.emplace_back(u2[0], u2[1]);
             }
             g.pairs.back().motion = motion_from_essential(*E, x1, x2);
           });
  return g;
}

bool is_forward_capture(const CaptureEvidence& e) {
  return e.read && e.strong_pairs > 0 && e.forward_pairs >= kForwardPairShare * e.strong_pairs;
}

CaptureEvidence summarize_capture(const CaptureGeometry& g) {
  CaptureEvidence e;
  e.read = true;
  e.photos = static_cast<int>(g.names.size());
  e.verified_pairs = static_cast<int>(g.pairs.size());
  std::map<int, int> partners, placeable;
  std::map<int, const PairGeometry*> strongest;  // per photo: its pair with the most inliers
  std::vector<double> forward_angles;
  for (const PairGeometry& p : g.pairs) {
    e.max_inliers = std::max(e.max_inliers, p.inliers);
    for (const int id : {p.image1, p.image2}) {
      ++partners[id];
      if (p.inliers >= kPlaceableInliers) ++placeable[id];
      const PairGeometry*& s = strongest[id];
      if (!s || p.inliers > s->inliers) s = &p;
    }
    if (!p.motion || p.inliers < kColmapInitMinInliers) continue;
    ++e.strong_pairs;
    forward_angles.push_back(std::acos(std::clamp(p.motion->forward, 0.0, 1.0)) * kDeg);
    if (p.motion->forward >= kColmapInitMaxForwardMotion)
      ++e.forward_pairs;
    else if (p.motion->median_tri_angle_deg >= kColmapInitMinTriAngleDeg)
      ++e.default_start_pairs;
  }
  std::vector<double> partner_counts, neighbour_angles;
  std::vector<int> ids;
  for (const auto& [id, name] : g.names) ids.push_back(id);
  std::sort(ids.begin(), ids.end(), [&](int a, int b) { return g.names.at(a) < g.names.at(b); });
  std::map<int, int> rank;  // position in name order
  for (size_t i = 0; i < ids.size(); ++i) rank[ids[i]] = static_cast<int>(i);
  for (const int id : ids) {
    partner_counts.push_back(partners[id]);
    if (placeable[id] < kPlaceableMinPartners) ++e.poorly_matched_photos;
    const auto it = strongest.find(id);
    if (it == strongest.end()) continue;
    const PairGeometry& p = *it->second;
    const int other = p.image1 == id ? p.image2 : p.image1;
    if (rank.count(other) && std::abs(rank[other] - rank[id]) <= 2) ++e.sequential_photos;
    if (p.motion) neighbour_angles.push_back(p.motion->median_tri_angle_deg);
  }
  if (!partner_counts.empty()) e.median_partners = median(partner_counts);
  if (!forward_angles.empty()) e.median_forward_angle_deg = median(forward_angles);
  if (!neighbour_angles.empty()) e.median_neighbour_tri_angle_deg = median(neighbour_angles);
  e.forward = is_forward_capture(e);

  char line[640];
  std::snprintf(line, sizeof line,
                "%d photos, %d verified pairs (median %.0f partners per photo, at most %d inliers), %d photo(s) "
                "with fewer than %d partners of %d inliers; %d strong pairs (>= %d inliers): %d move within 18 deg "
                "of the viewing direction (median angle %.1f deg), %d could start colmap's default mapper "
                "(< 18 deg forward, >= %.0f deg triangulation); strongest-neighbour triangulation angle %.1f deg "
                "(median); %d of %d photos matched best with a photo at most 2 names away",
                e.photos, e.verified_pairs, e.median_partners, e.max_inliers, e.poorly_matched_photos,
                kPlaceableMinPartners, kPlaceableInliers, e.strong_pairs, kColmapInitMinInliers, e.forward_pairs,
                e.median_forward_angle_deg, e.default_start_pairs, kColmapInitMinTriAngleDeg,
                e.median_neighbour_tri_angle_deg, e.sequential_photos, e.photos);
  e.summary = line;
  return e;
}

}  // namespace desplat::sfm
