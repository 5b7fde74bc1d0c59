// The images folder sorted into photos colmap can use and files it cannot, and what the photos
// say about their cameras; see include/desplat/sfm/sfm.hpp (scan_photos, choose_cameras).
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <map>
#include <tuple>

#include "desplat/io/jpeg_end.hpp"
#include "desplat/sfm/sfm.hpp"
#include "sfm/quoting.hpp"

namespace desplat::sfm {
namespace fs = std::filesystem;

namespace {

[[noreturn]] void bad_images(const std::string& message) { throw SfmError(SfmErrorKind::BadImages, message); }

// Formats colmap's image reader (FreeImage) handles that OpenImageIO can also check.
bool has_image_extension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  static const char* const kExtensions[] = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".ppm", ".pgm"};
  return std::any_of(std::begin(kExtensions), std::end(kExtensions), [&](const char* e) { return ext == e; });
}

// The camera facts colmap's image reader also uses: size, and EXIF make, model, focal length.
PhotoCamera camera_of(const OIIO::ImageSpec& spec) {
  PhotoCamera c;
  c.width = spec.width, c.height = spec.height;
  c.make = spec.get_string_attribute("Make");
  c.model = spec.get_string_attribute("Model");
  c.focal_mm = spec.get_float_attribute("Exif:FocalLength", 0.0f);
  return c;
}

// Why a file colmap would be given is not a usable photo ("" when it is one; then *camera is
// filled). colmap's reader skips such files quietly or, for a truncated JPEG, reads grey rows;
// either way the user must hear which file was left out and why.
std::string photo_problem(const fs::path& p, const fs::path& rel, PhotoCamera* camera) {
  if (!has_image_extension(p))
    return "not a photo (extension is not .jpg, .jpeg, .png, .tif, .tiff, .bmp, .ppm or .pgm)";
  if (rel.string().find_first_of("\r\n") != std::string::npos)
    return "its name holds a line break, which colmap's list of images cannot hold; rename it";
  std::error_code ec;
  if (fs::file_size(p, ec) == 0 && !ec) return "empty file (0 bytes)";
  auto in = OIIO::ImageInput::open(p.string());
  if (!in) {
    std::string why = OIIO::geterror();  // also clears OIIO's pending error
    if (why.empty()) why = "unknown format";
    return "cannot be opened as an image: " + why;
  }
  *camera = camera_of(in->spec());
  const std::string format = in->format_name();
  in->close();
  if (camera->width <= 0 || camera->height <= 0) return "the image has no pixels";
  try {
    if (format == "jpeg" && !jpeg_reaches_end_marker(p))
      return "the JPEG is truncated (its data stops before the end marker; a copy cut short?)";
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

std::string size_text(const PhotoCamera& c) { return std::to_string(c.width) + "x" + std::to_string(c.height); }

}  // namespace

PhotoScan scan_photos(const fs::path& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec))
    bad_images("the images folder " + in_quotes(dir) +
               " does not exist; pass the folder that holds your photos with --images");
  if (!fs::is_directory(dir, ec))
    bad_images(in_quotes(dir) + " is not a folder; --images takes the folder that holds your photos");
  std::vector<std::pair<fs::path, PhotoCamera>> photos;
  PhotoScan scan;
  fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec);
  if (ec) bad_images("cannot list the images folder " + in_quotes(dir) + ": " + ec.message());
  for (; it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) bad_images("cannot list the images folder " + in_quotes(dir) + ": " + ec.message());
    const fs::path& p = it->path();
    const std::string name = p.filename().string();
    if (name.empty() || name[0] == '.') {  // hidden files and folders (.DS_Store, .thumbnails)
      if (it->is_directory(ec)) it.disable_recursion_pending();
      continue;
    }
    if (!it->is_regular_file(ec)) continue;
    const fs::path rel = p.lexically_relative(dir);
    PhotoCamera camera;
    std::string problem = photo_problem(p, rel, &camera);
    if (problem.empty())
      photos.emplace_back(rel, camera);
    else
      scan.skipped.push_back({rel, std::move(problem)});
  }
  std::sort(photos.begin(), photos.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (auto& [path, camera] : photos) scan.photos.push_back(path), scan.cameras.push_back(camera);
  std::sort(scan.skipped.begin(), scan.skipped.end(),
            [](const SkippedFile& a, const SkippedFile& b) { return a.path < b.path; });
  return scan;
}

CameraChoice choose_cameras(CameraSharing requested, const std::vector<PhotoCamera>& cameras) {
  if (requested == CameraSharing::Single) return {true, "one shared camera, as asked (--cameras single)"};
  if (requested == CameraSharing::PerPhoto) return {false, "one camera per photo, as asked (--cameras per-photo)"};
  // Photos that agree on everything colmap's reader could tell apart are taken to share one lens
  // and zoom: sharing one calibration then constrains it with every photo instead of one.
  using Key = std::tuple<int, int, std::string, std::string, float>;
  std::map<Key, int> groups;
  for (const PhotoCamera& c : cameras) ++groups[{c.width, c.height, c.make, c.model, c.focal_mm}];
  const std::string n = std::to_string(cameras.size());
  if (groups.size() <= 1) {
    const std::string size = cameras.empty() ? "" : " " + size_text(cameras.front());
    return {true, "one shared camera: all " + n + " photos are" + size +
                      " with the same camera make, model and focal length in EXIF (or none recorded)"};
  }
  std::map<std::pair<int, int>, int> sizes;
  for (const PhotoCamera& c : cameras) ++sizes[{c.width, c.height}];
  std::string why = sizes.size() > 1 ? std::to_string(sizes.size()) + " image sizes"
                                     : "one size but " + std::to_string(groups.size()) + " EXIF camera/zoom settings";
  return {false, "one camera per photo: the " + n + " photos come in " + why};
}

const char* auto_camera_model(bool single_camera) { return single_camera ? "OPENCV" : "SIMPLE_RADIAL"; }

const char* camera_sharing_name(CameraSharing s) {
  switch (s) {
    case CameraSharing::Auto:
      return "auto";
    case CameraSharing::Single:
      return "single";
    case CameraSharing::PerPhoto:
      return "per-photo";
  }
  return "?";
}

std::optional<CameraSharing> camera_sharing_from_name(const std::string& name) {
  for (CameraSharing s : {CameraSharing::Auto, CameraSharing::Single, CameraSharing::PerPhoto})
    if (name == camera_sharing_name(s)) return s;
  return std::nullopt;
}

}  // namespace desplat::sfm
