// The relative motion of colmap's verified pairs, read from its database, and the capture
// evidence it gives (CaptureEvidence, include/desplat/sfm/sfm.hpp). Private to the sfm layer.
//
// colmap 3.8's matcher stores, per verified pair (image_id1 < image_id2), the inlier matches
// and F (x2ᵀ·F·x1 = 0 in pixels), E (the same for normalized coordinates, when the camera's
// focal length is known from EXIF) and H, but not the relative pose (qvec, tvec stay zero): the
// pose is recovered here from E, or from E = K2ᵀ·F·K1 with the cameras' initial intrinsics (the
// ones colmap's mapper starts from), choosing the decomposition that puts the most inliers in
// front of both cameras.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "desplat/sfm/sfm.hpp"

namespace desplat::sfm {

// Camera 2 relative to camera 1: p2 = R·p1 + t (colmap's two-view convention).
struct RelativeMotion {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::UnitZ();  // unit length
  int points_in_front = 0;                       // inliers triangulated in front of both cameras
  // |t_z|: the cosine of the angle between the baseline and camera 2's viewing direction, the
  // quantity colmap's Mapper.init_max_forward_motion bounds.
  double forward = 0;
  double median_tri_angle_deg = 0;  // over the points in front: the angle their two rays meet at
};

// The decomposition of E (x2ᵀ·E·x1 = 0, x = (u, v, 1) normalized image coordinates) that puts
// the most of the correspondences x1[i] ↔ x2[i] in front of both cameras; nullopt when E is
// zero, the inputs differ in length, or no correspondence lies in front.
std::optional<RelativeMotion> motion_from_essential(const Eigen::Matrix3d& E, const std::vector<Eigen::Vector2d>& x1,
                                                    const std::vector<Eigen::Vector2d>& x2);

struct PairGeometry {
  int image1 = 0, image2 = 0;  // colmap image ids, image1 < image2
  int inliers = 0;
  int config = 0;                        // colmap's TwoViewGeometry configuration (2 calibrated, 3 uncalibrated, ...)
  std::optional<RelativeMotion> motion;  // none without E or F (a homography-only pair) or usable points
};

struct CaptureGeometry {
  std::map<int, std::string> names;  // image id → name, every photo in the database
  std::vector<PairGeometry> pairs;   // the verified pairs (at least one inlier)
};

// Reads images, cameras, keypoints and two_view_geometries. Throws std::runtime_error naming the
// file when it is not a readable colmap database (a missing table or column included).
CaptureGeometry read_capture_geometry(const std::filesystem::path& database);

// The evidence of a capture's pairs, with the rule's verdict (is_forward_capture) and summary.
CaptureEvidence summarize_capture(const CaptureGeometry& geometry);

}  // namespace desplat::sfm
