// COLMAP capture -> Scene (see include/desplat/io/scene.hpp for the rules this implements).
#include "desplat/io/scene.hpp"

#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <map>
#include <optional>
#include <set>

#include "desplat/io/camera_models.hpp"
#include "desplat/io/masks.hpp"

namespace desplat {

void report_warning(const WarningSink& sink, const std::string& message) {
  if (sink)
    sink(message);
  else
    std::cerr << "desplat: warning: " << message << "\n";
}

namespace {

namespace fs = std::filesystem;

// ---- Folders, model, image headers ------------------------------------------------------------

fs::path require_dir(const fs::path& dir, const std::string& what) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw SceneError(dir.string() + ": missing " + what + " folder");
  return dir;
}

// The cache must not land in the input, which may be read-only or shared.
void require_outside(const fs::path& cache, const fs::path& data) {
  std::error_code ec;
  const fs::path rel = fs::weakly_canonical(cache, ec).lexically_relative(fs::weakly_canonical(data, ec));
  if (!rel.empty() && *rel.begin() != "..")
    throw SceneError(cache.string() + ": the image cache must be outside the input folder " + data.string());
}

colmap::Model read_model_or_throw(const fs::path& sparse) {
  try {
    return colmap::read_model(sparse);
  } catch (const colmap::ColmapError& e) {
    throw SceneError(e.what());  // already names the file, place and problem
  }
}

// The images file read_model used (it prefers the binary model).
fs::path model_images_file(const fs::path& sparse) {
  return fs::exists(sparse / "cameras.bin") ? sparse / "images.bin" : sparse / "images.txt";
}

fs::path model_cameras_file(const fs::path& sparse) {
  return fs::exists(sparse / "cameras.bin") ? sparse / "cameras.bin" : sparse / "cameras.txt";
}

struct Size {
  int width = 0, height = 0;
};

// Size from the file's header, without decoding the pixels.
Size read_image_size(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw SceneError(path.string() + ": image file is missing");
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) throw SceneError(path.string() + ": cannot read image: " + OIIO::geterror());
  return {in->spec().width, in->spec().height};
}

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// ---- Normalization and poses -------------------------------------------------------------------

// In Eigen rather than GLM: Eigen's normalized() adds the four squares unfused (one SIMD
// packet) and divides by the root, while GLM's scalar sums and mat3_cast's products fuse under
// the build's FMA contraction, and every Camera trained on comes from here, so trained models
// would change in their last bits (tests/test_pose_math.cpp compares the two).
Eigen::Matrix3d rotation_of(const colmap::Image& image) {
  const auto& q = image.qvec_wxyz;
  return Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
}

Eigen::Vector3d center_of(const colmap::Image& image) {
  const Eigen::Vector3d t(image.tvec[0], image.tvec[1], image.tvec[2]);
  return -(rotation_of(image).transpose() * t);
}

WorldNormalization normalization_of(const colmap::Model& model) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [id, image] : model.images) mean += center_of(image);
  mean /= static_cast<double>(model.images.size());
  double extent = 0;
  for (const auto& [id, image] : model.images)
    extent = std::max(extent, (center_of(image) - mean).cwiseAbs().maxCoeff());
  WorldNormalization n;
  n.center = {mean.x(), mean.y(), mean.z()};
  n.scale = extent > 0 ? 1.0 / extent : 1.0;  // one camera (or coincident ones): keep the scale
  return n;
}

// Every camera before any photo is read: positive, finite focal lengths and finite parameters.
void check_cameras(const colmap::Model& model, const fs::path& sparse) {
  for (const auto& [id, lens] : model.cameras) {
    const std::string who = model_cameras_file(sparse).string() + ": camera " + std::to_string(id) + " (" +
                            colmap::camera_model_info(lens.model).name + ")";
    for (size_t k = 0; k < lens.params.size(); ++k)
      if (!std::isfinite(lens.params[k]))
        throw SceneError(who + ": parameter " + std::to_string(k) + " is not a finite number; fix the camera");
    // Positive as the rasterizer's float, too (1e-300 px would become 0 there).
    const PinholeIntrinsics K = pinhole_intrinsics(lens);
    const float fx = float(K.fx), fy = float(K.fy);
    if (!(fx > 0) || !(fy > 0) || !std::isfinite(fx) || !std::isfinite(fy)) {
      char focal[96];
      std::snprintf(focal, sizeof focal, K.fx == K.fy ? "%g" : "%g, %g", K.fx, K.fy);
      throw SceneError(who + ": focal length " + focal + " px; a focal length must be a positive number of pixels (" +
                       colmap::camera_model_info(lens.model).param_names + "); fix the camera");
    }
  }
}

// The poses must span a baseline and look at the sparse points: coincident cameras, or a
// scene whose cameras see none of its points, cannot be reconstructed (docs/METHOD.md §4).
void check_poses(const colmap::Model& model, const WorldNormalization& n, const fs::path& sparse) {
  if (model.images.size() >= 2) {
    // Coincident up to rounding: within a billionth of the positions' magnitude.
    const Eigen::Vector3d first = center_of(model.images.begin()->second);
    double spread = 0;
    for (const auto& [id, image] : model.images) spread = std::max(spread, (center_of(image) - first).norm());
    if (spread <= 1e-9 * (1.0 + first.norm()))
      throw SceneError(model_images_file(sparse).string() + ": all " + std::to_string(model.images.size()) +
                       " cameras sit at one position, so there is no baseline to reconstruct depth from; the poses "
                       "are not a reconstruction (run desplat_sfm on the photos)");
  }
  if (model.points.empty()) return;
  // Points that span a billionth of the cameras' spread are in other units than the poses: they
  // would collapse to a pixel in every view.
  Eigen::Vector3d point_mean = Eigen::Vector3d::Zero();
  for (const auto& [pid, point] : model.points) point_mean += Eigen::Vector3d(point.xyz[0], point.xyz[1], point.xyz[2]);
  point_mean /= double(model.points.size());
  double point_extent = 0;
  for (const auto& [pid, point] : model.points)
    for (int k = 0; k < 3; ++k) point_extent = std::max(point_extent, std::abs(point.xyz[k] - point_mean[k]));
  if (model.points.size() >= 2 && n.scale != 1.0 && point_extent * n.scale < 1e-9)
    throw SceneError(model_images_file(sparse).string() + ": the cameras spread over " + std::to_string(1.0 / n.scale) +
                     " units but the sparse points only over " + std::to_string(point_extent) +
                     ": the camera positions and the points are not in the same units (run desplat_sfm on the photos)");
  size_t seen = 0;
  for (const auto& [id, image] : model.images) {
    const colmap::Camera& lens = model.cameras.at(image.camera_id);
    const PinholeIntrinsics K = pinhole_intrinsics(lens);
    const Eigen::Matrix3d R = rotation_of(image);
    const Eigen::Vector3d t(image.tvec[0], image.tvec[1], image.tvec[2]);
    for (const auto& [pid, point] : model.points) {
      const Eigen::Vector3d x = R * Eigen::Vector3d(point.xyz[0], point.xyz[1], point.xyz[2]) + t;
      if (!(x.z() > 0)) continue;
      const double u = K.fx * x.x() / x.z() + K.cx, v = K.fy * x.y() / x.z() + K.cy;
      if (u >= 0 && v >= 0 && u < double(lens.width) && v < double(lens.height)) {
        ++seen;
        break;
      }
    }
    if (seen) return;
  }
  throw SceneError(model_images_file(sparse).string() + ": none of the " + std::to_string(model.images.size()) +
                   " cameras sees any of the " + std::to_string(model.points.size()) +
                   " sparse points in front of it and inside its image; the poses and the points do not belong "
                   "together (run desplat_sfm on the photos)");
}

// The rasterizer's camera: intrinsics of the undistorted pinhole, pose in the normalized frame.
Camera view_camera(const colmap::Image& image, const colmap::Camera& pinhole, const WorldNormalization& n) {
  const Eigen::Matrix3d R = rotation_of(image);
  const Eigen::Vector3d c(n.center[0], n.center[1], n.center[2]);
  const Eigen::Vector3d t = (R * c + Eigen::Vector3d(image.tvec[0], image.tvec[1], image.tvec[2])) * n.scale;
  Camera cam;
  cam.fx = static_cast<float>(pinhole.params[0]);
  cam.fy = static_cast<float>(pinhole.params[1]);
  cam.cx = static_cast<float>(pinhole.params[2]);
  cam.cy = static_cast<float>(pinhole.params[3]);
  cam.width = static_cast<int>(pinhole.width);
  cam.height = static_cast<int>(pinhole.height);
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) cam.R_cw[3 * r + col] = static_cast<float>(R(r, col));
    cam.t_cw[r] = static_cast<float>(t(r));
  }
  return cam;
}

// ---- Sources: images/ or images_N/ ------------------------------------------------------------

struct Source {
  fs::path dir;
  std::map<std::string, Size> sizes;  // by image name
};

// Reads the header of every used view's file in `dir`; sizes must match the model's cameras.
Source originals(const fs::path& images_dir, const fs::path& model_file, const colmap::Model& model,
                 const std::vector<const colmap::Image*>& used) {
  Source src{images_dir, {}};
  for (const colmap::Image* image : used) {
    const fs::path path = images_dir / image->name;
    std::error_code ec;
    if (!fs::is_regular_file(path, ec))
      throw SceneError(path.string() + ": no file for image '" + image->name + "' (image id " +
                       std::to_string(image->id) + " in " + model_file.string() + ")");
    const Size s = read_image_size(path);
    const colmap::Camera& cam = model.cameras.at(image->camera_id);
    if (uint64_t(s.width) != cam.width || uint64_t(s.height) != cam.height)
      throw SceneError(path.string() + ": image is " + size_text(s.width, s.height) + " px but its COLMAP camera " +
                       std::to_string(cam.id) + " is " + size_text(int(cam.width), int(cam.height)) + " px");
    src.sizes[image->name] = s;
  }
  return src;
}

bool within_one_pixel(int actual, uint64_t original, int n) {
  return std::abs(static_cast<double>(actual) - static_cast<double>(original) / n) < 1.0;
}

// images_N/ when it is complete and its sizes fit W/N × H/N; otherwise the reason it is not.
std::optional<Source> downscaled_folder(const fs::path& dir, int n, const colmap::Model& model,
                                        const std::vector<const colmap::Image*>& used, std::string& why_not) {
  Source src{dir, {}};
  for (const colmap::Image* image : used) {
    const fs::path path = dir / image->name;
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) {
      why_not = path.string() + " is missing";
      return std::nullopt;
    }
    Size s;
    try {
      s = read_image_size(path);
    } catch (const SceneError& e) {
      why_not = e.what();
      return std::nullopt;
    }
    const colmap::Camera& cam = model.cameras.at(image->camera_id);
    if (!within_one_pixel(s.width, cam.width, n) || !within_one_pixel(s.height, cam.height, n)) {
      why_not = path.string() + " is " + size_text(s.width, s.height) + " px, expected " +
                size_text(int(cam.width) / n, int(cam.height) / n) + " (the camera's " +
                size_text(int(cam.width), int(cam.height)) + " / " + std::to_string(n) + ")";
      return std::nullopt;
    }
    src.sizes[image->name] = s;
  }
  return src;
}

// ---- Cache --------------------------------------------------------------------------------------

uint64_t fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

std::string camera_key(const colmap::Camera& c) {
  char buf[64];
  std::string s =
      std::to_string(static_cast<int>(c.model)) + " " + std::to_string(c.width) + " " + std::to_string(c.height);
  for (double p : c.params) {
    std::snprintf(buf, sizeof buf, " %.17g", p);
    s += buf;
  }
  return s;
}

bool needs_processing(const SceneView& v) {
  return uint64_t(v.source_width) != v.distorted_camera.width ||
         uint64_t(v.source_height) != v.distorted_camera.height ||
         camera_model_math(v.distorted_camera.model).has_distortion;
}

fs::path cache_path(const Scene& scene, const SceneView& v) {
  std::error_code ec;
  const fs::path source = fs::absolute(v.image_path).lexically_normal();
  const auto bytes = fs::file_size(source, ec);
  const auto mtime = fs::last_write_time(source, ec);
  if (ec) throw SceneError(source.string() + ": cannot read the image file: " + ec.message());
  const std::string key = "desplat view cache 1\n" + source.string() + "\n" + std::to_string(bytes) + "\n" +
                          std::to_string(mtime.time_since_epoch().count()) + "\n" + std::to_string(scene.downscale) +
                          "\n" + camera_key(v.distorted_camera) + "\n" + camera_key(v.undistorted_camera);
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(fnv1a(key)));
  return scene.cache_dir / "views" / (v.image_path.stem().string() + "-" + hash + ".png");
}

// Writes next to `path` and renames into place, so readers never see a partial file.
void write_atomically(const fs::path& path, const FloatImage& image) {
  static std::atomic<unsigned> counter{0};
  const fs::path tmp = path.parent_path() / (path.stem().string() + ".tmp" + std::to_string(::getpid()) + "-" +
                                             std::to_string(counter++) + ".png");
  try {
    write_image(tmp, image);
    fs::rename(tmp, path);
  } catch (const std::exception& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw SceneError("cannot write the image cache " + path.string() + ": " + e.what());
  }
}

void warn(const WarningSink& sink, std::vector<std::string>* log, const std::string& message) {
  if (log) log->push_back(message);
  report_warning(sink, message);
}

FloatImage read_checked(const fs::path& path, int width, int height) {
  FloatImage img;
  try {
    img = read_image_rgb(path);
  } catch (const ImageError& e) {
    throw SceneError(e.what());
  }
  if (img.width != width || img.height != height)
    throw SceneError(path.string() + ": image is now " + size_text(img.width, img.height) + " px, expected " +
                     size_text(width, height) + " (it changed after the scene was loaded)");
  return img;
}

// The source pixels resized to the training size and undistorted.
FloatImage process(const SceneView& v) {
  FloatImage img = read_checked(v.image_path, v.source_width, v.source_height);
  img = resize_area(img, int(v.distorted_camera.width), int(v.distorted_camera.height));
  return undistort_image(img, v.distorted_camera, v.undistorted_camera);
}

// ---- Assembly -------------------------------------------------------------------------------------

std::vector<const colmap::Image*> sorted_by_name(const colmap::Model& model) {
  std::vector<const colmap::Image*> images;
  for (const auto& [id, image] : model.images) images.push_back(&image);
  std::sort(images.begin(), images.end(), [](auto* a, auto* b) { return a->name < b->name; });
  return images;
}

// Picks images_N/ or images/ for the used views.
Source choose_source(const fs::path& data, const SceneOptions& options, const fs::path& model_file,
                     const colmap::Model& model, const std::vector<const colmap::Image*>& used, Scene& scene) {
  const fs::path images_dir = data / "images";
  const int n = options.downscale;
  const fs::path scaled = data / ("images_" + std::to_string(n));
  std::error_code ec;
  if (n > 1 && fs::is_directory(scaled, ec)) {
    std::string why_not;
    if (auto src = downscaled_folder(scaled, n, model, used, why_not)) return *src;
    warn(options.on_warning, &scene.warnings,
         "ignoring " + scaled.string() + ": " + why_not + "; downscaling " + images_dir.string() + " instead");
  }
  return originals(images_dir, model_file, model, used);
}

void add_points(const colmap::Model& model, const fs::path& sparse, const SceneOptions& options, Scene& scene) {
  std::map<uint32_t, uint32_t> view_of_image;  // COLMAP image id → index into scene.views
  for (size_t v = 0; v < scene.views.size(); ++v) view_of_image[scene.views[v].colmap_image_id] = uint32_t(v);
  for (const auto& [id, p] : model.points) {
    const auto x = scene.normalization.to_normalized(p.xyz);
    scene.points_xyz.push_back({float(x[0]), float(x[1]), float(x[2])});
    scene.points_rgb.push_back(p.rgb);
    scene.point_ids.push_back(id);
    std::set<uint32_t> images;
    std::set<uint32_t> views;
    for (const colmap::TrackElement& t : p.track) {
      images.insert(t.image_id);
      if (const auto it = view_of_image.find(t.image_id); it != view_of_image.end()) views.insert(it->second);
    }
    scene.point_track_images.push_back(uint32_t(images.size()));
    scene.point_views.emplace_back(views.begin(), views.end());
  }
  if (model.points.empty())
    warn(options.on_warning, &scene.warnings,
         sparse.string() + ": the model has no 3D points; training will start from random points");
}

// The view's ground-truth distractor mask (masks.hpp), or empty when the file does not exist.
fs::path existing_mask(const fs::path& data, const std::string& image_name) {
  const fs::path mask = distractor_mask_path(data, image_name);
  std::error_code ec;
  return fs::is_regular_file(mask, ec) ? mask : fs::path();
}

// The user's masks folder: the one given (it must exist), else <data>/masks when present.
fs::path user_masks_dir(const fs::path& data, const SceneOptions& options) {
  std::error_code ec;
  if (!options.masks_dir.empty()) {
    const fs::path dir = fs::absolute(options.masks_dir).lexically_normal();
    if (!fs::is_directory(dir, ec)) throw SceneError("the masks folder " + dir.string() + " does not exist");
    return dir;
  }
  return fs::is_directory(data / "masks", ec) ? data / "masks" : fs::path();
}

// <dir>/<name>.png (COLMAP's naming), else <dir>/<name with .png for its extension>
// (nerfstudio's); empty when neither exists.
fs::path existing_user_mask(const fs::path& dir, const std::string& image_name) {
  if (dir.empty()) return {};
  std::error_code ec;
  for (const fs::path& candidate : {dir / (image_name + ".png"), dir / fs::path(image_name).replace_extension(".png")})
    if (fs::is_regular_file(candidate, ec)) return candidate;
  return {};
}

}  // namespace

std::vector<size_t> Scene::train_views() const {
  std::vector<size_t> out;
  for (size_t i = 0; i < views.size(); ++i)
    if (!views[i].is_test) out.push_back(i);
  return out;
}

std::vector<size_t> Scene::test_views() const {
  std::vector<size_t> out;
  for (size_t i = 0; i < views.size(); ++i)
    if (views[i].is_test) out.push_back(i);
  return out;
}

fs::path default_cache_dir() {
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return fs::path(xdg) / "desplat";
  if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache" / "desplat";
  return fs::temp_directory_path() / "desplat-cache";
}

Scene load_colmap_scene(const fs::path& data_dir, const SceneOptions& options) {
  if (options.downscale < 1) throw SceneError("downscale must be at least 1, got " + std::to_string(options.downscale));
  const fs::path data = fs::absolute(data_dir).lexically_normal();
  require_dir(data, "scene");
  require_dir(data / "images", "images/");
  const fs::path sparse = require_dir(data / "sparse" / "0", "sparse/0/");
  const colmap::Model model = read_model_or_throw(sparse);
  if (model.images.empty())
    throw SceneError(model_images_file(sparse).string() + ": the model has no registered images");

  Scene scene;
  scene.data_dir = data;
  scene.downscale = options.downscale;
  scene.cache_dir = fs::absolute(options.cache_dir.empty() ? default_cache_dir() : options.cache_dir);
  require_outside(scene.cache_dir, data);
  scene.on_warning = options.on_warning;
  scene.normalization = normalization_of(model);
  check_cameras(model, sparse);
  check_poses(model, scene.normalization, sparse);

  const std::vector<const colmap::Image*> images = sorted_by_name(model);
  std::vector<std::string> names;
  for (const auto* image : images) names.push_back(image->name);
  std::vector<ViewRole> roles;
  try {
    roles = assign_split(names, options.split);
  } catch (const SplitError& e) {
    throw SceneError(e.what());
  }
  std::vector<const colmap::Image*> used;
  for (size_t i = 0; i < images.size(); ++i)
    if (roles[i] != ViewRole::Unused) used.push_back(images[i]);

  const Source source = choose_source(data, options, model_images_file(sparse), model, used, scene);
  const fs::path masks_dir = user_masks_dir(data, options);
  scene.masks_dir = masks_dir;
  std::set<uint32_t> strongly_distorted;  // cameras warned about
  for (size_t i = 0; i < images.size(); ++i) {
    if (roles[i] == ViewRole::Unused) continue;
    const colmap::Image& image = *images[i];
    const colmap::Camera& lens = model.cameras.at(image.camera_id);
    const Size src = source.sizes.at(image.name);
    const bool own_resize = source.dir == data / "images";
    const uint64_t w = own_resize ? std::max<uint64_t>(1, lens.width / options.downscale) : uint64_t(src.width);
    const uint64_t h = own_resize ? std::max<uint64_t>(1, lens.height / options.downscale) : uint64_t(src.height);
    SceneView v;
    v.name = image.name;
    v.image_path = source.dir / image.name;
    v.is_test = roles[i] == ViewRole::Test;
    v.colmap_image_id = image.id;
    v.source_width = src.width;
    v.source_height = src.height;
    v.photo_width = int(lens.width);
    v.photo_height = int(lens.height);
    v.mask_path = existing_mask(data, image.name);
    v.user_mask_path = existing_user_mask(masks_dir, image.name);
    v.distorted_camera = w == lens.width && h == lens.height ? lens : rescale_camera(lens, w, h);
    try {
      v.undistorted_camera = undistort_camera(v.distorted_camera, options.undistort);
    } catch (const std::invalid_argument& e) {
      throw SceneError(sparse.string() + ": camera " + std::to_string(lens.id) + ": " + e.what());
    }
    if ((2 * v.undistorted_camera.width < w || 2 * v.undistorted_camera.height < h) &&
        strongly_distorted.insert(lens.id).second)
      report_warning(scene.on_warning,
                     model_cameras_file(sparse).string() + ": camera " + std::to_string(lens.id) +
                         ": undistorting it keeps only " + std::to_string(v.undistorted_camera.width) + "x" +
                         std::to_string(v.undistorted_camera.height) + " of the " + std::to_string(w) + "x" +
                         std::to_string(h) + " image; its distortion coefficients are unusually strong: check them");
    // Clipped at the smallest undistorted size: the distortion folds the border back, which no
    // real lens does.
    if (double(v.undistorted_camera.width) <= options.undistort.min_scale * double(w) + 1 ||
        double(v.undistorted_camera.height) <= options.undistort.min_scale * double(h) + 1)
      throw SceneError(model_cameras_file(sparse).string() + ": camera " + std::to_string(lens.id) + " (" +
                       colmap::camera_model_info(lens.model).name +
                       "): its distortion coefficients bend the image "
                       "border so far that undistorting keeps at most " +
                       std::to_string(int(100 * options.undistort.min_scale)) +
                       "% of each side; they are not a real lens's: check the camera's parameters (" +
                       colmap::camera_model_info(lens.model).param_names + ")");
    v.camera = view_camera(image, v.undistorted_camera, scene.normalization);
    scene.views.push_back(std::move(v));
  }
  if (!masks_dir.empty()) {
    const auto unmasked = std::count_if(scene.views.begin(), scene.views.end(),
                                        [](const SceneView& v) { return v.user_mask_path.empty(); });
    if (unmasked == static_cast<long>(scene.views.size()))
      throw SceneError("the masks folder " + masks_dir.string() + " holds no mask for any photo (expected e.g. " +
                       (masks_dir / (scene.views.front().name + ".png")).string() + ")");
    if (unmasked > 0)
      warn(options.on_warning, &scene.warnings,
           masks_dir.string() + " has no mask for " + std::to_string(unmasked) + " of " +
               std::to_string(scene.views.size()) + " photos; every pixel of those is used");
  }
  add_points(model, sparse, options, scene);
  return scene;
}

fs::path view_cache_path(const Scene& scene, size_t view) {
  if (view >= scene.views.size())
    throw SceneError("view " + std::to_string(view) + " does not exist (the scene has " +
                     std::to_string(scene.views.size()) + ")");
  const SceneView& v = scene.views[view];
  return needs_processing(v) ? cache_path(scene, v) : fs::path();
}

FloatImage load_view_image(const Scene& scene, size_t view) {
  const fs::path cached = view_cache_path(scene, view);
  const SceneView& v = scene.views[view];
  const int w = v.camera.width, h = v.camera.height;
  if (cached.empty()) return read_checked(v.image_path, w, h);
  std::error_code ec;
  if (fs::exists(cached, ec)) {
    try {
      return read_checked(cached, w, h);
    } catch (const SceneError& e) {
      warn(scene.on_warning, nullptr, std::string("rebuilding a bad cache file: ") + e.what());
    }
  }
  fs::create_directories(cached.parent_path(), ec);
  if (ec)
    throw SceneError("cannot create the image cache folder " + cached.parent_path().string() + ": " + ec.message());
  write_atomically(cached, process(v));
  return read_checked(cached, w, h);  // what every later load returns, bit for bit
}

}  // namespace desplat
