// COLMAP sparse models: camera-model table, model checks, binary (.bin) read/write and the
// read_model dispatch. Text I/O lives in colmap_text.cpp.
//
// Binary layouts (COLMAP "Output Format"; all little-endian, no padding):
//   cameras.bin  u64 count; per camera: u32 id, i32 model id, u64 width, u64 height,
//                f64 params[num_params(model)]
//   images.bin   u64 count; per image: u32 id, f64 q[4] (w, x, y, z), f64 t[3], u32 camera_id,
//                NUL-terminated name, u64 num_points2D, then (f64 x, f64 y, u64 point3D_id)
//                each, with 2^64 − 1 meaning "no 3D point"
//   points3D.bin u64 count; per point: u64 id, f64 xyz[3], u8 rgb[3], f64 error,
//                u64 track_length, then (u32 image_id, u32 point2D_idx) each
#include "desplat/io/colmap.hpp"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <unordered_map>

namespace desplat::colmap {

static_assert(std::endian::native == std::endian::little,
              "COLMAP .bin files are little-endian; this reader copies bytes as-is");

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
    {CameraModelId::FullOpenCV, "FULL_OPENCV", 12,
     "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6"},
    {CameraModelId::FOV, "FOV", 5, "fx, fy, cx, cy, omega"},
    {CameraModelId::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4, "f, cx, cy, k"},
    {CameraModelId::RadialFisheye, "RADIAL_FISHEYE", 5, "f, cx, cy, k1, k2"},
    {CameraModelId::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12,
     "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1"},
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

// Shortest decimal that reads back as the same double: messages show the exact bad value.
std::string num(double v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

template <class T>
std::string num(T v)
  requires std::is_integral_v<T>
{
  return std::to_string(v);
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
      throw ColmapError(file_prefix(paths.images) + "image " + num(id) + ": camera_id " +
                        num(image.camera_id) + " is not in " + paths.cameras.string());
    const auto [it, fresh] = by_name.emplace(image.name, id);
    if (!fresh)
      throw ColmapError(file_prefix(paths.images) + "duplicate image name '" + image.name +
                        "' (images " + num(it->second) + " and " + num(id) + ")");
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
      const std::string who = file_prefix(paths.points) + "point3D " + num(pid) + " track[" +
                              num(k) + "]: ";
      const auto image = model.images.find(el.image_id);
      if (image == model.images.end())
        throw ColmapError(who + "image " + num(el.image_id) + " is not in " +
                          paths.images.string());
      const auto& obs = image->second.points2d;
      if (el.point2d_idx >= obs.size())
        throw ColmapError(who + "point2D_idx " + num(el.point2d_idx) + " is out of range (image " +
                          num(el.image_id) + " has " + num(obs.size()) + " points2D)");
      const int64_t back = obs[el.point2d_idx].point3d_id;
      if (back < 0 || static_cast<uint64_t>(back) != pid)
        throw ColmapError(who + "image " + num(el.image_id) + " points2D[" +
                          num(el.point2d_idx) + "] has point3D_id " + num(back) + ", not " +
                          num(pid));
      uint8_t& seen = claimed[el.image_id][el.point2d_idx];
      if (seen)
        throw ColmapError(who + "image " + num(el.image_id) + " points2D[" +
                          num(el.point2d_idx) + "] is listed twice");
      seen = 1;
    }
  }

  for (const auto& [id, image] : model.images) {
    const auto& seen = claimed[id];
    for (size_t k = 0; k < image.points2d.size(); ++k) {
      const int64_t pid = image.points2d[k].point3d_id;
      if (pid < 0 || seen[k]) continue;
      const std::string who = file_prefix(paths.images) + "image " + num(id) + " points2D[" +
                              num(k) + "]: ";
      if (!model.points.contains(static_cast<uint64_t>(pid)))
        throw ColmapError(who + "point3D " + num(pid) + " is not in " + paths.points.string());
      throw ColmapError(who + "point3D " + num(pid) + "'s track does not list this observation");
    }
  }
}

// ---- Binary reading -----------------------------------------------------------------------

// Smallest encoded size of each record: counts are checked against the bytes left before
// anything is allocated, so a corrupt count cannot trigger a huge allocation.
constexpr size_t kCameraMinBytes = 4 + 4 + 8 + 8;               // params come on top
constexpr size_t kImageMinBytes = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;  // empty name, no points
constexpr size_t kObservationBytes = 8 + 8 + 8;
constexpr size_t kPointMinBytes = 8 + 3 * 8 + 3 + 8 + 8;          // empty track
constexpr size_t kTrackElementBytes = 4 + 4;
constexpr uint64_t kInvalidPoint3DId = std::numeric_limits<uint64_t>::max();

// Bounds-checked cursor over a whole .bin file; every failure names the file, the byte
// offset and the record being read.
class BinaryReader {
 public:
  explicit BinaryReader(fs::path path) : path_(std::move(path)), data_(detail::read_file(path_)) {}

  size_t offset() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }
  void set_record(std::string record) { record_ = std::move(record); }

  template <class T>
  T get(const char* field) {
    if (remaining() < sizeof(T))
      fail("truncated: " + std::string(field) + " needs " + num(sizeof(T)) + " bytes, only " +
           num(remaining()) + " left");
    T value;
    std::memcpy(&value, data_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }

  template <class T, size_t N>
  void get(std::array<T, N>& out, const char* field) {
    for (T& v : out) v = get<T>(field);
  }

  // NUL-terminated string; the search stops at the end of the file.
  std::string get_cstring(const char* field) {
    const char* start = data_.data() + pos_;
    const void* nul = std::memchr(start, '\0', remaining());
    if (!nul)
      fail("truncated: " + std::string(field) + " has no terminating NUL byte before the end of "
           "the file (" + num(remaining()) + " bytes left)");
    std::string s(start, static_cast<const char*>(nul));
    pos_ += s.size() + 1;
    return s;
  }

  // A u64 count followed by records of at least `min_bytes` each.
  uint64_t get_count(const char* what, size_t min_bytes) {
    const size_t at = pos_;
    const auto count = get<uint64_t>(what);
    if (count > remaining() / min_bytes)
      fail_at(at, "count of " + std::string(what) + " is " + num(count) + " but each needs at "
              "least " + num(min_bytes) + " bytes and only " + num(remaining()) +
              " bytes remain (corrupt or truncated file)");
    return count;
  }

  void expect_end() {
    record_.clear();
    if (remaining() != 0)
      fail(num(remaining()) + " trailing bytes after the last record (expected end of file)");
  }

  [[noreturn]] void fail(const std::string& problem) const { fail_at(pos_, problem); }
  [[noreturn]] void fail_at(size_t at, const std::string& problem) const {
    std::string where = path_.string() + ": byte " + num(at) + ": ";
    if (!record_.empty()) where += record_ + ": ";
    throw ColmapError(where + problem);
  }

  // Runs a record check; its message is reported at the record's start offset.
  template <class F>
  void check_record(size_t at, F&& check) const {
    try {
      check();
    } catch (const ColmapError& e) {
      fail_at(at, e.what());
    }
  }

 private:
  fs::path path_;
  std::string data_;
  size_t pos_ = 0;
  std::string record_;  // "image record 3 of 50", for messages
};

std::string record_label(const char* kind, uint64_t i, uint64_t n) {
  return std::string(kind) + " record " + num(i + 1) + " of " + num(n);
}

std::map<uint32_t, Camera> read_cameras_binary(const fs::path& path) {
  BinaryReader in(path);
  std::map<uint32_t, Camera> cameras;
  const uint64_t n = in.get_count("cameras", kCameraMinBytes);
  for (uint64_t i = 0; i < n; ++i) {
    in.set_record(record_label("camera", i, n));
    const size_t at = in.offset();
    Camera cam;
    cam.id = in.get<uint32_t>("camera_id");
    const auto model_id = in.get<int32_t>("model_id");
    cam.model = static_cast<CameraModelId>(model_id);
    const CameraModelInfo* info = find_model(cam.model);
    if (!info) in.fail_at(at, "camera " + num(cam.id) + ": unknown camera model id " + num(model_id));
    cam.width = in.get<uint64_t>("width");
    cam.height = in.get<uint64_t>("height");
    cam.params.resize(static_cast<size_t>(info->num_params));
    for (double& p : cam.params) p = in.get<double>("params");
    in.check_record(at, [&] { check_camera(cam); });
    const uint32_t id = cam.id;
    if (!cameras.emplace(id, std::move(cam)).second)
      in.fail_at(at, "duplicate camera id " + num(id));
  }
  in.expect_end();
  return cameras;
}

Observation read_observation(BinaryReader& in, uint64_t k) {
  Observation obs;
  obs.x = in.get<double>("points2D x");
  obs.y = in.get<double>("points2D y");
  const auto id = in.get<uint64_t>("points2D point3D_id");
  if (id == kInvalidPoint3DId) {
    obs.point3d_id = kNoPoint3D;
  } else if (id > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
    in.fail("points2D[" + num(k) + "] has point3D_id " + num(id) +
            ", beyond the signed 64-bit range (only 2^64 - 1, 'none', is allowed there)");
  } else {
    obs.point3d_id = static_cast<int64_t>(id);
  }
  return obs;
}

std::map<uint32_t, Image> read_images_binary(const fs::path& path) {
  BinaryReader in(path);
  std::map<uint32_t, Image> images;
  const uint64_t n = in.get_count("images", kImageMinBytes);
  for (uint64_t i = 0; i < n; ++i) {
    in.set_record(record_label("image", i, n));
    const size_t at = in.offset();
    Image img;
    img.id = in.get<uint32_t>("image_id");
    in.get(img.qvec_wxyz, "qvec");
    in.get(img.tvec, "tvec");
    img.camera_id = in.get<uint32_t>("camera_id");
    img.name = in.get_cstring("image name");
    const uint64_t num_points = in.get_count("points2D", kObservationBytes);
    img.points2d.resize(num_points);
    for (uint64_t k = 0; k < num_points; ++k) img.points2d[k] = read_observation(in, k);
    in.check_record(at, [&] { check_image(img); });
    const uint32_t id = img.id;
    if (!images.emplace(id, std::move(img)).second)
      in.fail_at(at, "duplicate image id " + num(id));
  }
  in.expect_end();
  return images;
}

std::map<uint64_t, Point3D> read_points_binary(const fs::path& path) {
  BinaryReader in(path);
  std::map<uint64_t, Point3D> points;
  const uint64_t n = in.get_count("points3D", kPointMinBytes);
  for (uint64_t i = 0; i < n; ++i) {
    in.set_record(record_label("point3D", i, n));
    const size_t at = in.offset();
    Point3D pt;
    pt.id = in.get<uint64_t>("point3D_id");
    in.get(pt.xyz, "xyz");
    in.get(pt.rgb, "rgb");
    pt.error = in.get<double>("error");
    const uint64_t length = in.get_count("track elements", kTrackElementBytes);
    pt.track.resize(length);
    for (TrackElement& el : pt.track) {
      el.image_id = in.get<uint32_t>("track image_id");
      el.point2d_idx = in.get<uint32_t>("track point2D_idx");
    }
    in.check_record(at, [&] { check_point(pt); });
    const uint64_t id = pt.id;
    if (!points.emplace(id, std::move(pt)).second)
      in.fail_at(at, "duplicate point3D id " + num(id));
  }
  in.expect_end();
  return points;
}

// ---- Binary writing -----------------------------------------------------------------------

class BinaryWriter {
 public:
  template <class T>
  void put(T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    out_.append(bytes, sizeof(T));
  }
  template <class T, size_t N>
  void put(const std::array<T, N>& values) {
    for (T v : values) put(v);
  }
  void put_cstring(const std::string& s) {
    out_ += s;
    out_.push_back('\0');
  }
  const std::string& bytes() const { return out_; }

 private:
  std::string out_;
};

std::string encode_cameras(const std::map<uint32_t, Camera>& cameras) {
  BinaryWriter w;
  w.put<uint64_t>(cameras.size());
  for (const auto& [id, cam] : cameras) {
    w.put<uint32_t>(cam.id);
    w.put<int32_t>(static_cast<int32_t>(cam.model));
    w.put<uint64_t>(cam.width);
    w.put<uint64_t>(cam.height);
    for (double p : cam.params) w.put(p);
  }
  return w.bytes();
}

std::string encode_images(const std::map<uint32_t, Image>& images) {
  BinaryWriter w;
  w.put<uint64_t>(images.size());
  for (const auto& [id, img] : images) {
    w.put<uint32_t>(img.id);
    w.put(img.qvec_wxyz);
    w.put(img.tvec);
    w.put<uint32_t>(img.camera_id);
    w.put_cstring(img.name);
    w.put<uint64_t>(img.points2d.size());
    for (const Observation& obs : img.points2d) {
      w.put(obs.x);
      w.put(obs.y);
      w.put<uint64_t>(obs.point3d_id == kNoPoint3D ? kInvalidPoint3DId
                                                   : static_cast<uint64_t>(obs.point3d_id));
    }
  }
  return w.bytes();
}

std::string encode_points(const std::map<uint64_t, Point3D>& points) {
  BinaryWriter w;
  w.put<uint64_t>(points.size());
  for (const auto& [id, pt] : points) {
    w.put<uint64_t>(pt.id);
    w.put(pt.xyz);
    w.put(pt.rgb);
    w.put(pt.error);
    w.put<uint64_t>(pt.track.size());
    for (const TrackElement& el : pt.track) {
      w.put<uint32_t>(el.image_id);
      w.put<uint32_t>(el.point2d_idx);
    }
  }
  return w.bytes();
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
  if (!info)
    throw ColmapError(who + "unknown camera model id " + num(static_cast<int>(camera.model)));
  if (camera.params.size() != static_cast<size_t>(info->num_params))
    throw ColmapError(who + info->name + " needs " + num(info->num_params) + " params (" +
                      info->param_names + "), got " + num(camera.params.size()));
  if (camera.width == 0) throw ColmapError(who + "width must be positive, got 0");
  if (camera.height == 0) throw ColmapError(who + "height must be positive, got 0");
  for (size_t i = 0; i < camera.params.size(); ++i)
    if (!std::isfinite(camera.params[i]))
      throw ColmapError(who + "param " + num(i) + " (" + param_name(*info, i) + ") is " +
                        num(camera.params[i]));
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
    throw ColmapError(who + "quaternion has zero norm (" + num(q[0]) + ", " + num(q[1]) + ", " +
                      num(q[2]) + ", " + num(q[3]) + ")");
  for (size_t k = 0; k < 3; ++k)
    if (!std::isfinite(image.tvec[k]))
      throw ColmapError(who + kT[k] + " is " + num(image.tvec[k]));
  if (image.name.empty()) throw ColmapError(who + "empty image name");
  if (image.name.find('\0') != std::string::npos)
    throw ColmapError(who + "image name contains a NUL byte");
  for (size_t k = 0; k < image.points2d.size(); ++k) {
    const Observation& obs = image.points2d[k];
    if (!std::isfinite(obs.x) || !std::isfinite(obs.y))
      throw ColmapError(who + "points2D[" + num(k) + "] is (" + num(obs.x) + ", " + num(obs.y) +
                        ")");
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
      throw ColmapError(file_prefix(paths.cameras) + "camera map key " + num(id) +
                        " holds camera id " + num(cam.id));
    with_prefix(file_prefix(paths.cameras), [&camera = cam] { check_camera(camera); });
  }
  for (const auto& [id, img] : model.images) {
    if (id != img.id)
      throw ColmapError(file_prefix(paths.images) + "image map key " + num(id) +
                        " holds image id " + num(img.id));
    with_prefix(file_prefix(paths.images), [&image = img] { check_image(image); });
  }
  for (const auto& [id, pt] : model.points) {
    if (id != pt.id)
      throw ColmapError(file_prefix(paths.points) + "point3D map key " + num(id) +
                        " holds point3D id " + num(pt.id));
    with_prefix(file_prefix(paths.points), [&point = pt] { check_point(point); });
  }
  check_image_references(model, paths);
  check_tracks(model, paths);
}

// ---- Files --------------------------------------------------------------------------------

namespace detail {

std::string read_file(const fs::path& path) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status)) throw ColmapError(path.string() + ": file not found");
  if (!fs::is_regular_file(status)) throw ColmapError(path.string() + ": not a regular file");
  std::ifstream file(path, std::ios::binary);
  if (!file) throw ColmapError(path.string() + ": cannot open for reading");
  std::ostringstream bytes;
  bytes << file.rdbuf();
  if (file.bad() || bytes.bad()) throw ColmapError(path.string() + ": read error");
  return std::move(bytes).str();
}

void write_file(const fs::path& path, std::string_view bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) throw ColmapError(path.string() + ": cannot open for writing");
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();
  if (!file) throw ColmapError(path.string() + ": write error");
}

void make_directory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw ColmapError(dir.string() + ": cannot create directory: " + ec.message());
}

}  // namespace detail

// ---- Public binary I/O --------------------------------------------------------------------

Model read_model_binary(const fs::path& dir) {
  const ModelPaths paths = ModelPaths::binary(dir);
  Model model;
  model.cameras = read_cameras_binary(paths.cameras);
  model.images = read_images_binary(paths.images);
  model.points = read_points_binary(paths.points);
  validate_model(model, paths);
  return model;
}

void write_model_binary(const Model& model, const fs::path& dir) {
  const ModelPaths paths = ModelPaths::binary(dir);
  validate_model(model, paths);  // never write a model we would refuse to read
  detail::make_directory(dir);
  detail::write_file(paths.cameras, encode_cameras(model.cameras));
  detail::write_file(paths.images, encode_images(model.images));
  detail::write_file(paths.points, encode_points(model.points));
}

Model read_model(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw ColmapError(dir.string() + ": COLMAP model directory not found");
  if (fs::exists(ModelPaths::binary(dir).cameras, ec)) return read_model_binary(dir);
  if (fs::exists(ModelPaths::text(dir).cameras, ec)) return read_model_text(dir);
  throw ColmapError(dir.string() + ": no COLMAP model: neither " +
                    ModelPaths::binary(dir).cameras.string() + " nor " +
                    ModelPaths::text(dir).cameras.string() + " exists");
}

}  // namespace desplat::colmap
