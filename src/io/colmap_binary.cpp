// COLMAP sparse models in the binary format (.bin files).
//
// Binary layouts (COLMAP "Output Format"; all little-endian, no padding):
//   cameras.bin  u64 count; per camera: u32 id, i32 model id, u64 width, u64 height,
//                f64 params[num_params(model)]
//   images.bin   u64 count; per image: u32 id, f64 q[4] (w, x, y, z), f64 t[3], u32 camera_id,
//                NUL-terminated name, u64 num_points2D, then (f64 x, f64 y, u64 point3D_id)
//                each, with 2^64 − 1 meaning "no 3D point"
//   points3D.bin u64 count; per point: u64 id, f64 xyz[3], u8 rgb[3], f64 error,
//                u64 track_length, then (u32 image_id, u32 point2D_idx) each
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "desplat/io/colmap.hpp"
#include "io/colmap_files.hpp"

namespace desplat::colmap {

static_assert(std::endian::native == std::endian::little,
              "COLMAP .bin files are little-endian; this reader copies bytes as-is");

namespace fs = std::filesystem;

namespace {

// ---- Binary reading -----------------------------------------------------------------------

// Smallest encoded size of each record: counts are checked against the bytes left before
// anything is allocated, so a corrupt count cannot trigger a huge allocation.
constexpr size_t kCameraMinBytes = 4 + 4 + 8 + 8;                 // params come on top
constexpr size_t kImageMinBytes = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;  // empty name, no points
constexpr size_t kObservationBytes = 8 + 8 + 8;
constexpr size_t kPointMinBytes = 8 + 3 * 8 + 3 + 8 + 8;  // empty track
constexpr size_t kTrackElementBytes = 4 + 4;
constexpr uint64_t kInvalidPoint3DId = std::numeric_limits<uint64_t>::max();

// Bounds-checked cursor over a whole .bin file; every failure names the file, the byte
// offset and the record being read.
class BinaryReader {
 public:
  explicit BinaryReader(fs::path path) : path_(std::move(path)), data_(read_file(path_)) {}

  size_t offset() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }
  void set_record(std::string record) { record_ = std::move(record); }

  template <class T>
  T get(const char* field) {
    if (remaining() < sizeof(T))
      fail("truncated: " + std::string(field) + " needs " + num(sizeof(T)) + " bytes, only " + num(remaining()) +
           " left");
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
      fail("truncated: " + std::string(field) +
           " has no terminating NUL byte before the end of "
           "the file (" +
           num(remaining()) + " bytes left)");
    std::string s(start, static_cast<const char*>(nul));
    pos_ += s.size() + 1;
    return s;
  }

  // A u64 count followed by records of at least `min_bytes` each.
  uint64_t get_count(const char* what, size_t min_bytes) {
    const size_t at = pos_;
    const auto count = get<uint64_t>(what);
    if (count > remaining() / min_bytes)
      fail_at(at, "count of " + std::string(what) + " is " + num(count) +
                      " but each needs at "
                      "least " +
                      num(min_bytes) + " bytes and only " + num(remaining()) +
                      " bytes remain (corrupt or truncated file)");
    return count;
  }

  void expect_end() {
    record_.clear();
    if (remaining() != 0) fail(num(remaining()) + " trailing bytes after the last record (expected end of file)");
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
    if (model_id < 0 || size_t(model_id) >= camera_models().size())
      in.fail_at(at, "camera " + num(cam.id) + ": unknown camera model id " + num(model_id));
    const CameraModelInfo* info = &camera_model_info(cam.model);
    cam.width = in.get<uint64_t>("width");
    cam.height = in.get<uint64_t>("height");
    cam.params.resize(static_cast<size_t>(info->num_params));
    for (double& p : cam.params) p = in.get<double>("params");
    in.check_record(at, [&] { check_camera(cam); });
    const uint32_t id = cam.id;
    if (!cameras.emplace(id, std::move(cam)).second) in.fail_at(at, "duplicate camera id " + num(id));
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
    if (!images.emplace(id, std::move(img)).second) in.fail_at(at, "duplicate image id " + num(id));
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
    if (!points.emplace(id, std::move(pt)).second) in.fail_at(at, "duplicate point3D id " + num(id));
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
      w.put<uint64_t>(obs.point3d_id == kNoPoint3D ? kInvalidPoint3DId : static_cast<uint64_t>(obs.point3d_id));
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
  make_directory(dir);
  write_file(paths.cameras, encode_cameras(model.cameras));
  write_file(paths.images, encode_images(model.images));
  write_file(paths.points, encode_points(model.points));
}

}  // namespace desplat::colmap
