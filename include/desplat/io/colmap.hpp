// COLMAP sparse models: cameras, images and points3D in COLMAP's binary (.bin) and text
// (.txt) forms, with the layouts of COLMAP's "Output Format" documentation.
//
// Frames and units (docs/METHOD.md §1):
//   * Image::qvec_wxyz and Image::tvec are the world-to-camera rotation (Hamilton quaternion,
//     w first) and translation: p_cam = R(q)·p_world + t; the camera center is −R(q)ᵀ·t.
//     The camera looks along +z, x right, y down. q is kept exactly as stored in the file
//     (not renormalized), so write(read(f)) reproduces f; normalize it before use.
//   * Camera::params and Observation x, y are in pixels of a width × height image; COLMAP puts
//     the center of pixel (i, j) at (i + 0.5, j + 0.5). The meaning of each parameter is given
//     by the model's CameraModelInfo::param_names (e.g. OPENCV: fx, fy, cx, cy, k1, k2, p1, p2).
//   * Point3D::xyz is in the model's world units; rgb is 0..255; error is the mean
//     reprojection error in pixels as COLMAP stored it (not checked: it is diagnostic only).
//
// Ownership: plain value types. Readers return a Model by value; writers take it by const
// reference, create the directory if needed and overwrite existing files.
// Thread safety: no shared state; concurrent calls are safe unless they write the same files.
// Host byte order must be little-endian (checked at compile time).
//
// Errors: every problem is a ColmapError (never a crash, an unbounded read or allocation, or a
// silently different model). The message starts with the full path of the offending file,
// then the place (byte offset for .bin, line number for .txt) and the record, then the
// problem with the value that broke it, e.g.
//   "/d/cameras.txt:4: camera 1: OPENCV needs 8 params (fx, fy, cx, cy, k1, k2, p1, p2), got 7".
// Readers enforce (and writers enforce before touching any file) every check listed at
// check_camera, check_image, check_point and validate_model, plus the format's own rules:
// counts that fit in the bytes that remain, no bytes after the last record, no duplicate ids,
// well-formed text lines.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace desplat::colmap {

class ColmapError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// COLMAP's camera model ids (the int32 stored in cameras.bin).
enum class CameraModelId : int {
  SimplePinhole = 0,
  Pinhole = 1,
  SimpleRadial = 2,
  Radial = 3,
  OpenCV = 4,
  OpenCVFisheye = 5,
  FullOpenCV = 6,
  FOV = 7,
  SimpleRadialFisheye = 8,
  RadialFisheye = 9,
  ThinPrismFisheye = 10,
};

struct CameraModelInfo {
  CameraModelId id;
  const char* name;         // as in cameras.txt, e.g. "OPENCV"
  int num_params;           // length of Camera::params
  const char* param_names;  // e.g. "fx, fy, cx, cy, k1, k2, p1, p2"
};

// Every model COLMAP 3.8 defines, in id order.
const std::vector<CameraModelInfo>& camera_models();
// Throws ColmapError naming the id when it is not one of CameraModelId's values.
const CameraModelInfo& camera_model_info(CameraModelId id);
// Exact, case-sensitive: "OPENCV" -> OpenCV; nullopt for anything else.
std::optional<CameraModelId> camera_model_from_name(std::string_view name);

struct Camera {
  uint32_t id = 0;
  CameraModelId model = CameraModelId::Pinhole;
  uint64_t width = 0, height = 0;  // [px]
  std::vector<double> params;      // [camera_model_info(model).num_params], see param_names
  friend bool operator==(const Camera&, const Camera&) = default;
};

inline constexpr int64_t kNoPoint3D = -1;

struct Observation {
  double x = 0, y = 0;              // keypoint position [px]
  int64_t point3d_id = kNoPoint3D;  // -1: not triangulated (stored as 2^64 − 1 in images.bin)
  friend bool operator==(const Observation&, const Observation&) = default;
};

struct Image {
  uint32_t id = 0;
  std::array<double, 4> qvec_wxyz{1, 0, 0, 0};  // world-to-camera rotation (w, x, y, z)
  std::array<double, 3> tvec{0, 0, 0};          // world-to-camera translation [world units]
  uint32_t camera_id = 0;
  std::string name;                   // image file path relative to the image folder
  std::vector<Observation> points2d;  // indexed by TrackElement::point2d_idx
  friend bool operator==(const Image&, const Image&) = default;
};

struct TrackElement {
  uint32_t image_id = 0;
  uint32_t point2d_idx = 0;  // index into that image's points2d
  friend bool operator==(const TrackElement&, const TrackElement&) = default;
};

struct Point3D {
  uint64_t id = 0;
  std::array<double, 3> xyz{0, 0, 0};  // world position [world units]
  std::array<uint8_t, 3> rgb{0, 0, 0};
  double error = 0;  // mean reprojection error [px]
  std::vector<TrackElement> track;
  friend bool operator==(const Point3D&, const Point3D&) = default;
};

// Keyed by id; each key equals the id inside its record.
struct Model {
  std::map<uint32_t, Camera> cameras;
  std::map<uint32_t, Image> images;
  std::map<uint64_t, Point3D> points;
  friend bool operator==(const Model&, const Model&) = default;
};

// Reads dir/cameras.bin, images.bin, points3D.bin if dir/cameras.bin exists, otherwise the
// .txt files; a ColmapError naming both candidates when neither exists.
Model read_model(const std::filesystem::path& dir);
Model read_model_binary(const std::filesystem::path& dir);
Model read_model_text(const std::filesystem::path& dir);

// Doubles are written exactly: raw bytes in .bin, 17 significant digits in .txt (as COLMAP
// does; exact for our reader and for COLMAP's, which parses via long double).
// Text caveat: names are read back as the rest of the line, so names with inner spaces
// round-trip through our reader, but COLMAP's own text reader stops at the first space.
// Names with line breaks or leading/trailing whitespace cannot be written as text.
void write_model_binary(const Model& model, const std::filesystem::path& dir);
void write_model_text(const Model& model, const std::filesystem::path& dir);

// ---- Checks shared by readers and writers ------------------------------------------------
// Record checks throw ColmapError with a message naming the record ("camera 3: ...") but no
// file; callers prefix the file and position.

// Known model id, params.size() == num_params, all params finite, width > 0, height > 0.
void check_camera(const Camera& camera);
// Finite qvec with norm > 1e-12, finite tvec, non-empty name without NUL that is a relative
// path with no '..' component (names become paths under the image and output folders),
// finite observation x, y, point3d_id ≥ −1.
void check_image(const Image& image);
// Finite xyz.
void check_point(const Point3D& point);

// Files named by validate_model's messages.
struct ModelPaths {
  std::filesystem::path cameras, images, points;
  static ModelPaths binary(const std::filesystem::path& dir);  // dir/cameras.bin, ...
  static ModelPaths text(const std::filesystem::path& dir);    // dir/cameras.txt, ...
};

// Whole-model checks: every record as above; map keys equal record ids; every image's
// camera_id is a camera; image names unique; tracks and observations agree both ways (each
// track element names an existing image and an in-range points2d index whose point3d_id is
// this point, no observation is listed twice, and every observation with a point3d_id is
// listed in that point's track). Messages start with the path of the file the bad record
// belongs to.
void validate_model(const Model& model, const ModelPaths& paths);

}  // namespace desplat::colmap
