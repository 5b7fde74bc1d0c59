// COLMAP sparse models, the data: the camera-model table and the record and whole-model checks
// every reader and writer applies. The file formats are colmap_binary.cpp and colmap_text.cpp.
#include "desplat/io/colmap.hpp"
#include "io/colmap_files.hpp"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <unordered_map>

#include <nlohmann/json.hpp>

namespace desplat::colmap {

namespace fs = std::filesystem;

namespace {

// ---- Camera-model table -------------------------------------------------------------------

// Indexed by CameraModelId (COLMAP 3.8's ids and parameter orders).
const std::vector<CameraModelInfo> kCameraModels = {
    {CameraModelId::SimplePinhole, "SIMPLE_PINHOLE", 3, "f, cx, cy"},
    {CameraModelId::Pinhole, "PINHOLE", 4, "fx, fy, cx, cy"},
    {CameraModelId::SimpleRadial, "SIMPLE_RADIAL", 4, "f, cx, cy, k"},
    {CameraModelId::Radial, "RADIAL", 5, "f, cx, cy, k1, k2"},
    {CameraModelId::OpenCV, "OPENCV", 8, "fx, fy, cx, cy, k1, k2, p1, p2"},
    {CameraModelId::OpenCVFisheye, "OPENCV_FISHEYE", 8, "fx, fy, cx, cy, k1, k2, k3, k4"},
    {CameraModelId::FullOpenCV, "FULL_OPENCV", 12, "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6"},
    {CameraModelId::FOV, "FOV", 5, "fx, fy, cx, cy, omega"},
    {CameraModelId::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4, "f, cx, cy, k"},
    {CameraModelId::RadialFisheye, "RADIAL_FISHEYE", 5, "f, cx, cy, k1, k2"},
    {CameraModelId::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12, "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1"},
};

const CameraModelInfo* find_model(CameraModelId id) {
  const auto index = static_cast<int>(id);
  if (index < 0 || index >= static_cast<int>(kCameraModels.size())) return nullptr;
  return &kCameraModels[static_cast<size_t>(index)];
}

// The i-th name of a ", "-separated list (for messages).
std::string param_name(const CameraModelInfo& info, size_t i) {
  std::string_view names = info.param_names;
  for (; i > 0; --i) names.remove_prefix(names.find(", ") + 2);
  return std::string(names.substr(0, names.find(", ")));
}

// Runs `check`; a ColmapError from it gets `prefix` ("<file>: ...") in front.
template <class F>
void with_prefix(const std::string& prefix, F&& check) {
  try {
    check();
  } catch (const ColmapError& e) {
    throw ColmapError(prefix + e.what());
  }
}

std::string file_prefix(const fs::path& file) { return file.string() + ": "; }

// ---- Whole-model checks -------------------------------------------------------------------

void check_image_references(const Model& model, const ModelPaths& paths) {
  std::unordered_map<std::string_view, uint32_t> by_name;
  for (const auto& [id, image] : model.images) {
    if (!model.cameras.contains(image.camera_id))
      throw ColmapError(file_prefix(paths.images) + "image " + num(id) + ": camera_id " + num(image.camera_id) +
                        " is not in " + paths.cameras.string());
    const auto [it, fresh] = by_name.emplace(image.name, id);
    if (!fresh)
      throw ColmapError(file_prefix(paths.images) + "duplicate image name '" + image.name + "' (images " +
                        num(it->second) + " and " + num(id) + ")");
  }
  // Names go into JSON records (config.json, checkpoints, metrics), which hold UTF-8 only.
  for (const auto& [id, image] : model.images) {
    try {
      (void)nlohmann::json(image.name).dump();
    } catch (const nlohmann::json::type_error&) {
      std::string shown;
      for (const unsigned char ch : image.name)
        shown += ch >= 0x20 && ch < 0x7f ? std::string(1, char(ch))
                                         : "\\x" + std::string(1, "0123456789abcdef"[ch >> 4]) +
                                               std::string(1, "0123456789abcdef"[ch & 15]);
      throw ColmapError(file_prefix(paths.images) + "image " + num(id) + ": its name '" + shown +
                        "' is not UTF-8 text (e.g. Latin-1); rename the photo and its entry to UTF-8");
    }
  }
  // Two spellings of one file ("./a.jpg" and "a.jpg") would train one photo under two poses.
  std::unordered_map<std::string, uint32_t> by_file;
  for (const auto& [id, image] : model.images) {
    const std::string file = fs::path(image.name).lexically_normal().generic_string();
    const auto [it, fresh] = by_file.emplace(file, id);
    if (!fresh)
      throw ColmapError(file_prefix(paths.images) + "images " + num(it->second) + " ('" +
                        model.images.at(it->second).name + "') and " + num(id) + " ('" + image.name +
                        "') name the same file " + file + ": one photo cannot have two poses; remove one of them");
  }
}

// Each track element must name an observation that points back at its point, and each
// observation may be claimed once; afterwards every observation with a point3d_id must have
// been claimed, so tracks and observations describe the same correspondences.
void check_tracks(const Model& model, const ModelPaths& paths) {
  std::unordered_map<uint32_t, std::vector<uint8_t>> claimed;
  for (const auto& [id, image] : model.images) claimed[id].assign(image.points2d.size(), 0);

  for (const auto& [pid, point] : model.points) {
    for (size_t k = 0; k < point.track.size(); ++k) {
      const TrackElement& el = point.track[k];
      const std::string who = file_prefix(paths.points) + "point3D " + num(pid) + " track[" + num(k) + "]: ";
      const auto image = model.images.find(el.image_id);
      if (image == model.images.end())
        throw ColmapError(who + "image " + num(el.image_id) + " is not in " + paths.images.string());
      const auto& obs = image->second.points2d;
      if (el.point2d_idx >= obs.size())
        throw ColmapError(who + "point2D_idx " + num(el.point2d_idx) + " is out of range (image " + num(el.image_id) +
                          " has " + num(obs.size()) + " points2D)");
      const int64_t back = obs[el.point2d_idx].point3d_id;
      if (back < 0 || static_cast<uint64_t>(back) != pid)
        throw ColmapError(who + "image " + num(el.image_id) + " points2D[" + num(el.point2d_idx) + "] has point3D_id " +
                          num(back) + ", not " + num(pid));
      uint8_t& seen = claimed[el.image_id][el.point2d_idx];
      if (seen)
        throw ColmapError(who + "image " + num(el.image_id) + " points2D[" + num(el.point2d_idx) + "] is listed twice");
      seen = 1;
    }
  }

  for (const auto& [id, image] : model.images) {
    const auto& seen = claimed[id];
    for (size_t k = 0; k < image.points2d.size(); ++k) {
      const int64_t pid = image.points2d[k].point3d_id;
      if (pid < 0 || seen[k]) continue;
      const std::string who = file_prefix(paths.images) + "image " + num(id) + " points2D[" + num(k) + "]: ";
      if (!model.points.contains(static_cast<uint64_t>(pid)))
        throw ColmapError(who + "point3D " + num(pid) + " is not in " + paths.points.string());
      throw ColmapError(who + "point3D " + num(pid) + "'s track does not list this observation");
    }
  }
}

}  // namespace

// ---- Camera-model table (public) ----------------------------------------------------------

const std::vector<CameraModelInfo>& camera_models() { return kCameraModels; }

const CameraModelInfo& camera_model_info(CameraModelId id) {
  const CameraModelInfo* info = find_model(id);
  if (!info) throw ColmapError("unknown camera model id " + num(static_cast<int>(id)));
  return *info;
}

std::optional<CameraModelId> camera_model_from_name(std::string_view name) {
  for (const CameraModelInfo& info : kCameraModels)
    if (name == info.name) return info.id;
  return std::nullopt;
}

// ---- Record checks ------------------------------------------------------------------------

void check_camera(const Camera& camera) {
  const std::string who = "camera " + num(camera.id) + ": ";
  const CameraModelInfo* info = find_model(camera.model);
  if (!info) throw ColmapError(who + "unknown camera model id " + num(static_cast<int>(camera.model)));
  if (camera.params.size() != static_cast<size_t>(info->num_params))
    throw ColmapError(who + info->name + " needs " + num(info->num_params) + " params (" + info->param_names +
                      "), got " + num(camera.params.size()));
  if (camera.width == 0) throw ColmapError(who + "width must be positive, got 0");
  if (camera.height == 0) throw ColmapError(who + "height must be positive, got 0");
  for (size_t i = 0; i < camera.params.size(); ++i)
    if (!std::isfinite(camera.params[i]))
      throw ColmapError(who + "param " + num(i) + " (" + param_name(*info, i) + ") is " + num(camera.params[i]));
}

void check_image(const Image& image) {
  const std::string who = "image " + num(image.id) + ": ";
  const auto& q = image.qvec_wxyz;
  static constexpr const char* kQ[] = {"qw", "qx", "qy", "qz"};
  static constexpr const char* kT[] = {"tx", "ty", "tz"};
  for (size_t k = 0; k < 4; ++k)
    if (!std::isfinite(q[k])) throw ColmapError(who + kQ[k] + " is " + num(q[k]));
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(norm > 1e-12))
    throw ColmapError(who + "quaternion has zero norm (" + num(q[0]) + ", " + num(q[1]) + ", " + num(q[2]) + ", " +
                      num(q[3]) + ")");
  for (size_t k = 0; k < 3; ++k)
    if (!std::isfinite(image.tvec[k])) throw ColmapError(who + kT[k] + " is " + num(image.tvec[k]));
  if (image.name.empty()) throw ColmapError(who + "empty image name");
  if (image.name.find('\0') != std::string::npos) throw ColmapError(who + "image name contains a NUL byte");
  // Names become paths under the image folder and under output folders: nothing may lead out.
  const fs::path name_path(image.name);
  if (name_path.has_root_path())
    throw ColmapError(who + "image name '" + image.name +
                      "' is an absolute path; names must be relative to the image folder");
  for (const fs::path& part : name_path)
    if (part == "..")
      throw ColmapError(who + "image name '" + image.name +
                        "' leaves the image folder ('..'); names must stay inside it");
  for (size_t k = 0; k < image.points2d.size(); ++k) {
    const Observation& obs = image.points2d[k];
    if (!std::isfinite(obs.x) || !std::isfinite(obs.y))
      throw ColmapError(who + "points2D[" + num(k) + "] is (" + num(obs.x) + ", " + num(obs.y) + ")");
    if (obs.point3d_id < kNoPoint3D)
      throw ColmapError(who + "points2D[" + num(k) + "] has point3D_id " + num(obs.point3d_id) +
                        " (must be -1 or a point id)");
  }
}

void check_point(const Point3D& point) {
  static constexpr const char* kXYZ[] = {"x", "y", "z"};
  for (size_t k = 0; k < 3; ++k)
    if (!std::isfinite(point.xyz[k]))
      throw ColmapError("point3D " + num(point.id) + ": " + kXYZ[k] + " is " + num(point.xyz[k]));
}

ModelPaths ModelPaths::binary(const fs::path& dir) {
  return {dir / "cameras.bin", dir / "images.bin", dir / "points3D.bin"};
}

ModelPaths ModelPaths::text(const fs::path& dir) {
  return {dir / "cameras.txt", dir / "images.txt", dir / "points3D.txt"};
}

void validate_model(const Model& model, const ModelPaths& paths) {
  for (const auto& [id, cam] : model.cameras) {
    if (id != cam.id)
      throw ColmapError(file_prefix(paths.cameras) + "camera map key " + num(id) + " holds camera id " + num(cam.id));
    with_prefix(file_prefix(paths.cameras), [&camera = cam] { check_camera(camera); });
  }
  for (const auto& [id, img] : model.images) {
    if (id != img.id)
      throw ColmapError(file_prefix(paths.images) + "image map key " + num(id) + " holds image id " + num(img.id));
    with_prefix(file_prefix(paths.images), [&image = img] { check_image(image); });
  }
  for (const auto& [id, pt] : model.points) {
    if (id != pt.id)
      throw ColmapError(file_prefix(paths.points) + "point3D map key " + num(id) + " holds point3D id " + num(pt.id));
    with_prefix(file_prefix(paths.points), [&point = pt] { check_point(point); });
  }
  check_image_references(model, paths);
  check_tracks(model, paths);
}

}  // namespace desplat::colmap
