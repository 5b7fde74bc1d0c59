// COLMAP sparse models in text form (cameras.txt, images.txt, points3D.txt).
//
// Layout (COLMAP "Output Format"): lines whose first non-blank character is '#' are comments;
// fields are separated by spaces.
//   cameras.txt   CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]              (one line per camera)
//   images.txt    IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME       (two lines per image:
//                 X Y POINT3D_ID X Y POINT3D_ID ...                   the second may be empty;
//                                                                     POINT3D_ID −1 = none)
//   points3D.txt  POINT3D_ID X Y Z R G B ERROR (IMAGE_ID POINT2D_IDX)... (one line per point)
// Doubles are written like COLMAP writes them, with 17 significant digits ("%.17g"): that
// identifies every double exactly, and unlike the shortest round-trip decimal it also survives
// COLMAP's own reader, which parses through long double and so rounds twice (a shortest
// decimal near the midpoint of two doubles, e.g. 2.535696468129226, comes back 1 ulp off).
#include "desplat/io/colmap.hpp"
#include "io/colmap_files.hpp"

#include <algorithm>
#include <charconv>
#include <limits>
#include <type_traits>

namespace desplat::colmap {

namespace fs = std::filesystem;

namespace {

constexpr std::string_view kBlank = " \t\r";  // '\r': tolerate CRLF files

std::string_view trim(std::string_view s) {
  const size_t first = s.find_first_not_of(kBlank);
  if (first == std::string_view::npos) return {};
  return s.substr(first, s.find_last_not_of(kBlank) - first + 1);
}

std::vector<std::string_view> split_fields(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t pos = 0;
  while ((pos = line.find_first_not_of(kBlank, pos)) != std::string_view::npos) {
    const size_t end = std::min(line.find_first_of(kBlank, pos), line.size());
    fields.push_back(line.substr(pos, end - pos));
    pos = end;
  }
  return fields;
}

template <class T>
const char* integer_kind() {
  if constexpr (std::is_same_v<T, uint32_t>) return "an unsigned 32-bit integer";
  if constexpr (std::is_same_v<T, uint64_t>) return "an unsigned 64-bit integer";
  if constexpr (std::is_same_v<T, int64_t>) return "a signed 64-bit integer";
}

// A whole text file split into lines; failures name the file and the 1-based line number.
class TextFile {
 public:
  explicit TextFile(fs::path path) : path_(std::move(path)), data_(read_file(path_)) {
    std::string_view rest = data_;
    while (!rest.empty()) {
      const size_t eol = rest.find('\n');
      lines_.push_back(rest.substr(0, eol));
      if (eol == std::string_view::npos) break;
      rest.remove_prefix(eol + 1);
    }
  }

  size_t num_lines() const { return lines_.size(); }
  std::string_view line(size_t i) const { return lines_[i]; }

  // First line at or after i that is neither blank nor a comment; num_lines() if none.
  size_t next_data_line(size_t i) const {
    for (; i < lines_.size(); ++i) {
      const std::string_view t = trim(lines_[i]);
      if (!t.empty() && t.front() != '#') return i;
    }
    return i;
  }

  [[noreturn]] void fail(size_t i, const std::string& problem) const {
    throw ColmapError(path_.string() + ":" + std::to_string(i + 1) + ": " + problem);
  }

  // Runs a record check, reporting its failure at line i.
  template <class F>
  void check_line(size_t i, F&& check) const {
    try {
      check();
    } catch (const ColmapError& e) {
      fail(i, e.what());
    }
  }

 private:
  fs::path path_;
  std::string data_;
  std::vector<std::string_view> lines_;
};

// The fields of one line, with parsers that report the field name and offending text.
class LineFields {
 public:
  LineFields(const TextFile& file, size_t line) : file_(file), line_(line), fields_(split_fields(file.line(line))) {}

  size_t size() const { return fields_.size(); }
  std::string_view raw(size_t k) const { return fields_[k]; }

  // Everything from field k to the end of the line, trailing blanks removed.
  std::string_view rest_from(size_t k) const {
    const std::string_view whole = file_.line(line_);
    return trim(whole.substr(static_cast<size_t>(fields_[k].data() - whole.data())));
  }

  template <class T>
  T integer(size_t k, std::string_view field) const {
    T value{};
    const std::string_view s = fields_[k];
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (ec != std::errc() || end != s.data() + s.size())
      fail(std::string(field) + " '" + std::string(s) + "' is not " + integer_kind<T>());
    return value;
  }

  // Accepts what COLMAP writes (and "nan"/"inf", which the record checks then reject).
  double real(size_t k, std::string_view field) const {
    std::string_view s = fields_[k];
    if (s.size() > 1 && s.front() == '+' && s[1] != '-') s.remove_prefix(1);
    double value = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (ec != std::errc() || end != s.data() + s.size())
      fail(std::string(field) + " '" + std::string(fields_[k]) + "' is not a number");
    return value;
  }

  // Image sizes: parsed signed so that "-5" is reported as non-positive, not as garbage.
  uint64_t positive(size_t k, std::string_view field, std::string_view who) const {
    const auto value = integer<int64_t>(k, field);
    if (value <= 0) fail(std::string(who) + std::string(field) + " must be positive, got " + std::to_string(value));
    return static_cast<uint64_t>(value);
  }

  [[noreturn]] void fail(const std::string& problem) const { file_.fail(line_, problem); }

 private:
  const TextFile& file_;
  size_t line_;
  std::vector<std::string_view> fields_;
};

std::string indexed(std::string_view field, size_t k) { return std::string(field) + "[" + std::to_string(k) + "]"; }

// ---- Reading ------------------------------------------------------------------------------

Camera parse_camera(const LineFields& f) {
  if (f.size() < 4)
    f.fail("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got " + std::to_string(f.size()) + " fields");
  Camera cam;
  cam.id = f.integer<uint32_t>(0, "CAMERA_ID");
  const std::string who = "camera " + std::to_string(cam.id) + ": ";
  const auto model = camera_model_from_name(f.raw(1));
  if (!model) f.fail(who + "unknown camera model '" + std::string(f.raw(1)) + "'");
  cam.model = *model;
  cam.width = f.positive(2, "WIDTH", who);
  cam.height = f.positive(3, "HEIGHT", who);
  for (size_t k = 4; k < f.size(); ++k) cam.params.push_back(f.real(k, indexed("PARAMS", k - 4)));
  return cam;
}

std::map<uint32_t, Camera> read_cameras_text(const fs::path& path) {
  const TextFile file(path);
  std::map<uint32_t, Camera> cameras;
  for (size_t i = file.next_data_line(0); i < file.num_lines(); i = file.next_data_line(i + 1)) {
    Camera cam = parse_camera(LineFields(file, i));
    file.check_line(i, [&] { check_camera(cam); });
    const uint32_t id = cam.id;
    if (!cameras.emplace(id, std::move(cam)).second) file.fail(i, "duplicate camera id " + std::to_string(id));
  }
  return cameras;
}

Image parse_image_line(const LineFields& f) {
  if (f.size() < 10)
    f.fail("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got " + std::to_string(f.size()) + " fields");
  Image img;
  img.id = f.integer<uint32_t>(0, "IMAGE_ID");
  static constexpr const char* kQ[] = {"QW", "QX", "QY", "QZ"};
  static constexpr const char* kT[] = {"TX", "TY", "TZ"};
  for (size_t k = 0; k < 4; ++k) img.qvec_wxyz[k] = f.real(1 + k, kQ[k]);
  for (size_t k = 0; k < 3; ++k) img.tvec[k] = f.real(5 + k, kT[k]);
  img.camera_id = f.integer<uint32_t>(8, "CAMERA_ID");
  img.name = f.rest_from(9);  // names may contain spaces
  return img;
}

std::vector<Observation> parse_points2d_line(const LineFields& f) {
  if (f.size() % 3 != 0)
    f.fail("POINTS2D line has " + std::to_string(f.size()) + " fields, not a multiple of 3 (X Y POINT3D_ID)");
  std::vector<Observation> points(f.size() / 3);
  for (size_t k = 0; k < points.size(); ++k) {
    points[k].x = f.real(3 * k, indexed("X", k));
    points[k].y = f.real(3 * k + 1, indexed("Y", k));
    points[k].point3d_id = f.integer<int64_t>(3 * k + 2, indexed("POINT3D_ID", k));
  }
  return points;
}

std::map<uint32_t, Image> read_images_text(const fs::path& path) {
  const TextFile file(path);
  std::map<uint32_t, Image> images;
  for (size_t i = file.next_data_line(0); i < file.num_lines(); i = file.next_data_line(i + 2)) {
    Image img = parse_image_line(LineFields(file, i));
    // The POINTS2D line is the very next line, even when blank.
    if (i + 1 >= file.num_lines())
      file.fail(i, "image " + std::to_string(img.id) +
                       ": file ends before its POINTS2D line (the line after each image line; "
                       "it may be empty)");
    img.points2d = parse_points2d_line(LineFields(file, i + 1));
    file.check_line(i, [&] { check_image(img); });
    const uint32_t id = img.id;
    if (!images.emplace(id, std::move(img)).second) file.fail(i, "duplicate image id " + std::to_string(id));
  }
  return images;
}

Point3D parse_point(const LineFields& f) {
  if (f.size() < 8 || (f.size() - 8) % 2 != 0)
    f.fail(
        "expected POINT3D_ID X Y Z R G B ERROR followed by (IMAGE_ID POINT2D_IDX) pairs, "
        "got " +
        std::to_string(f.size()) + " fields");
  Point3D pt;
  pt.id = f.integer<uint64_t>(0, "POINT3D_ID");
  static constexpr const char* kXYZ[] = {"X", "Y", "Z"};
  static constexpr const char* kRGB[] = {"R", "G", "B"};
  for (size_t k = 0; k < 3; ++k) pt.xyz[k] = f.real(1 + k, kXYZ[k]);
  for (size_t k = 0; k < 3; ++k) {
    const auto c = f.integer<uint32_t>(4 + k, kRGB[k]);
    if (c > 255) f.fail(std::string(kRGB[k]) + " must be 0..255, got " + std::to_string(c));
    pt.rgb[k] = static_cast<uint8_t>(c);
  }
  pt.error = f.real(7, "ERROR");
  pt.track.resize((f.size() - 8) / 2);
  for (size_t k = 0; k < pt.track.size(); ++k) {
    pt.track[k].image_id = f.integer<uint32_t>(8 + 2 * k, indexed("IMAGE_ID", k));
    pt.track[k].point2d_idx = f.integer<uint32_t>(9 + 2 * k, indexed("POINT2D_IDX", k));
  }
  return pt;
}

std::map<uint64_t, Point3D> read_points_text(const fs::path& path) {
  const TextFile file(path);
  std::map<uint64_t, Point3D> points;
  for (size_t i = file.next_data_line(0); i < file.num_lines(); i = file.next_data_line(i + 1)) {
    Point3D pt = parse_point(LineFields(file, i));
    file.check_line(i, [&] { check_point(pt); });
    const uint64_t id = pt.id;
    if (!points.emplace(id, std::move(pt)).second) file.fail(i, "duplicate point3D id " + std::to_string(id));
  }
  return points;
}

// ---- Writing ------------------------------------------------------------------------------

// "%.17g": exact, and safe for readers that round twice (see the top of this file).
char* format_double(char* first, char* last, double v) {
  return std::to_chars(first, last, v, std::chars_format::general, 17).ptr;
}

std::string format_double(double v) {
  char buf[32];
  return std::string(buf, format_double(buf, buf + sizeof buf, v));
}

// Appends fields separated by single spaces.
class LineWriter {
 public:
  template <class T>
  LineWriter& operator<<(T value) requires std::is_arithmetic_v<T> {
    space();
    char buf[32];
    if constexpr (std::is_floating_point_v<T>)
      out_.append(buf, format_double(buf, buf + sizeof buf, static_cast<double>(value)));
    else
      out_.append(buf, std::to_chars(buf, buf + sizeof buf, value).ptr);
    return *this;
  }
  LineWriter& operator<<(std::string_view text) {
    space();
    out_ += text;
    return *this;
  }
  void end_line() {
    out_ += '\n';
    at_line_start_ = true;
  }
  void comment(std::string_view text) {
    out_ += text;
    end_line();
  }
  std::string& str() { return out_; }

 private:
  void space() {
    if (!at_line_start_) out_ += ' ';
    at_line_start_ = false;
  }
  std::string out_;
  bool at_line_start_ = true;
};

std::string encode_cameras(const std::map<uint32_t, Camera>& cameras) {
  LineWriter w;
  w.comment("# Camera list with one line of data per camera:");
  w.comment("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]");
  w.comment("# Number of cameras: " + std::to_string(cameras.size()));
  for (const auto& [id, cam] : cameras) {
    w << cam.id << camera_model_info(cam.model).name << cam.width << cam.height;
    for (double p : cam.params) w << p;
    w.end_line();
  }
  return std::move(w.str());
}

std::string encode_images(const std::map<uint32_t, Image>& images) {
  size_t observed = 0;
  for (const auto& [id, img] : images)
    for (const Observation& obs : img.points2d) observed += obs.point3d_id >= 0;
  const double mean = images.empty() ? 0.0 : double(observed) / double(images.size());

  LineWriter w;
  w.comment("# Image list with two lines of data per image:");
  w.comment("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME");
  w.comment("#   POINTS2D[] as (X, Y, POINT3D_ID)");
  w.comment("# Number of images: " + std::to_string(images.size()) +
            ", mean observations per image: " + format_double(mean));
  for (const auto& [id, img] : images) {
    w << img.id;
    for (double q : img.qvec_wxyz) w << q;
    for (double t : img.tvec) w << t;
    w << img.camera_id << std::string_view(img.name);
    w.end_line();
    for (const Observation& obs : img.points2d) w << obs.x << obs.y << obs.point3d_id;
    w.end_line();
  }
  return std::move(w.str());
}

std::string encode_points(const std::map<uint64_t, Point3D>& points) {
  size_t track_total = 0;
  for (const auto& [id, pt] : points) track_total += pt.track.size();
  const double mean = points.empty() ? 0.0 : double(track_total) / double(points.size());

  LineWriter w;
  w.comment("# 3D point list with one line of data per point:");
  w.comment("#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)");
  w.comment("# Number of points: " + std::to_string(points.size()) + ", mean track length: " + format_double(mean));
  for (const auto& [id, pt] : points) {
    w << pt.id;
    for (double c : pt.xyz) w << c;
    for (uint8_t c : pt.rgb) w << unsigned{c};
    w << pt.error;
    for (const TrackElement& el : pt.track) w << el.image_id << el.point2d_idx;
    w.end_line();
  }
  return std::move(w.str());
}

// The name is the rest of its line, so it must survive line splitting and trimming.
void check_names_writable(const Model& model, const fs::path& images_file) {
  for (const auto& [id, img] : model.images) {
    const bool breaks = img.name.find_first_of("\n\r") != std::string::npos;
    if (breaks || trim(img.name) != img.name)
      throw ColmapError(images_file.string() + ": image " + std::to_string(id) + ": name '" + img.name +
                        "' has a line break or leading/trailing blanks, which the "
                        "text format cannot store");
  }
}

}  // namespace

Model read_model_text(const fs::path& dir) {
  const ModelPaths paths = ModelPaths::text(dir);
  Model model;
  model.cameras = read_cameras_text(paths.cameras);
  model.images = read_images_text(paths.images);
  model.points = read_points_text(paths.points);
  validate_model(model, paths);
  return model;
}

void write_model_text(const Model& model, const fs::path& dir) {
  const ModelPaths paths = ModelPaths::text(dir);
  validate_model(model, paths);  // never write a model we would refuse to read
  check_names_writable(model, paths.images);
  make_directory(dir);
  write_file(paths.cameras, encode_cameras(model.cameras));
  write_file(paths.images, encode_images(model.images));
  write_file(paths.points, encode_points(model.points));
}

}  // namespace desplat::colmap
