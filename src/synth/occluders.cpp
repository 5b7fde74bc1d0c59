// desplat_occlude's job: pasting occluders (shapes and patches of other photos) into training
// views of a capture and writing the result as a scene with ground-truth distractor masks.
// See include/desplat/synth/occluders.hpp for what is written; the mask layout is masks.hpp's.
#include "desplat/synth/occluders.hpp"
#include "desplat/io/output_folder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>

#include "desplat/io/colmap.hpp"
#include "desplat/io/masks.hpp"
#include "desplat/io/photo_file.hpp"

namespace desplat {

namespace fs = std::filesystem;

namespace {

std::string number_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

void make_dirs(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw OccludeError(dir.string() + ": cannot create the folder: " + ec.message());
}

using Box = std::array<int, 4>;  // [x0, y0, x1, y1)

// Portable randomness: mt19937_64's output is fixed by the standard, but the std::
// distributions and std::shuffle are not, so they are written out here.
struct Random {
  std::mt19937_64 engine;
  explicit Random(uint64_t seed) : engine(seed) {}
  double uniform() { return double(engine() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  size_t index(size_t n) { return std::min(n - 1, size_t(uniform() * double(n))); }  // [0, n)
  int integer(int lo, int hi) { return lo + int(index(size_t(hi - lo + 1))); }       // [lo, hi]
};

uint64_t fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

// Each view draws from its own stream, so its occluders do not depend on the other views.
uint64_t view_seed(uint64_t seed, const std::string& name) {
  uint64_t z = seed ^ fnv1a(name);  // splitmix64 finalizer: nearby seeds give unrelated streams
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

struct Size {
  int width = 0, height = 0;
};

// The io layer's photo-file calls with their errors in this tool's type.
template <class Fn>
auto image_io(Fn&& fn) {
  try {
    return fn();
  } catch (const ImageError& e) {
    throw OccludeError(e.what());
  }
}

PhotoFile read_photo(const fs::path& path) {
  return image_io([&] { return read_photo_file(path); });
}

Size read_size(const fs::path& path) {
  return image_io([&] {
    const std::array<int, 2> s = read_image_size(path);
    return Size{s[0], s[1]};
  });
}

void write_photo(const fs::path& path, const PhotoFile& p) {
  image_io([&] { write_photo_file(path, p); });
}

void write_mask(const fs::path& path, const cv::Mat& mask) {
  make_dirs(path.parent_path());
  image_io([&] { write_mask_u8(path, mask.cols, mask.rows, mask.data); });
}

// ---- Shapes: a footprint (255 = covered) of the image's size ----

// Every pixel whose center lies inside the ellipse inscribed in the box.
void fill_ellipse(cv::Mat& footprint, double x0, double y0, double w, double h) {
  const double cx = x0 + w / 2, cy = y0 + h / 2, ax = w / 2, ay = h / 2;
  for (int y = std::max(0, int(y0)); y < std::min(footprint.rows, int(std::ceil(y0 + h))); ++y)
    for (int x = std::max(0, int(x0)); x < std::min(footprint.cols, int(std::ceil(x0 + w))); ++x) {
      const double u = (x + 0.5 - cx) / ax, v = (y + 0.5 - cy) / ay;
      if (u * u + v * v <= 1) footprint.at<uint8_t>(y, x) = 255;
    }
}

// A star-shaped polygon (5–8 vertices at jittered angles and radii) in unit coordinates.
std::vector<cv::Point2d> random_polygon(Random& rng) {
  const int n = rng.integer(5, 8);
  std::vector<cv::Point2d> pts;
  for (int k = 0; k < n; ++k) {
    const double angle = 2 * M_PI * (k + rng.uniform(-0.3, 0.3)) / n, radius = rng.uniform(0.45, 1.0);
    pts.emplace_back(radius * std::cos(angle), radius * std::sin(angle));
  }
  return pts;
}

// Share of its [-1, 1]² box the polygon covers (shoelace area / 4).
double box_share(const std::vector<cv::Point2d>& pts) {
  double twice_area = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const cv::Point2d& a = pts[i];
    const cv::Point2d& b = pts[(i + 1) % pts.size()];
    twice_area += a.x * b.y - b.x * a.y;
  }
  return std::abs(twice_area) / 8;
}

Box bounding_box(const cv::Mat& footprint) {
  Box b{footprint.cols, footprint.rows, 0, 0};
  for (int y = 0; y < footprint.rows; ++y)
    for (int x = 0; x < footprint.cols; ++x)
      if (footprint.at<uint8_t>(y, x))
        b = {std::min(b[0], x), std::min(b[1], y), std::max(b[2], x + 1), std::max(b[3], y + 1)};
  return b;
}

bool overlap(const Box& a, const Box& b) { return a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]; }

const char* const kKinds[] = {"ellipse", "rectangle", "polygon", "patch_rectangle", "patch_ellipse"};

struct Placed {
  Occluder occluder;
  cv::Mat footprint;  // CV_8U, the image's size
};

// One occluder of about `area` pixels inside a W×H image; nullopt when a patch finds no
// source place that does not overlap its destination.
std::optional<Placed> place_occluder(Random& rng, int W, int H, double area, const std::vector<std::string>& targets,
                                     const std::vector<std::string>& names, const std::map<std::string, Size>& sizes) {
  Placed p;
  p.occluder.kind = kKinds[rng.index(5)];
  const std::string& kind = p.occluder.kind;
  const bool elliptic = kind == "ellipse" || kind == "patch_ellipse";
  std::vector<cv::Point2d> polygon;
  double share = 1;
  if (elliptic) share = M_PI / 4;
  if (kind == "polygon") share = box_share(polygon = random_polygon(rng));
  // Box of the chosen aspect ratio (0.5–2) whose shape covers `area`, clipped to the image.
  const double aspect = std::exp(rng.uniform(std::log(0.5), std::log(2.0)));
  const int w = std::clamp(int(std::lround(std::sqrt(area / share * aspect))), 4, W);
  const int h = std::clamp(int(std::lround(area / share / w)), 4, H);
  const int x0 = rng.integer(0, W - w), y0 = rng.integer(0, H - h);

  p.footprint = cv::Mat::zeros(H, W, CV_8U);
  if (elliptic) {
    fill_ellipse(p.footprint, x0, y0, w, h);
  } else if (kind == "polygon") {
    std::vector<cv::Point> corners;
    for (const auto& q : polygon)
      corners.emplace_back(std::clamp(int(std::lround(x0 + (q.x + 1) / 2 * (w - 1))), 0, W - 1),
                           std::clamp(int(std::lround(y0 + (q.y + 1) / 2 * (h - 1))), 0, H - 1));
    cv::fillPoly(p.footprint, std::vector<std::vector<cv::Point>>{corners}, cv::Scalar(255), cv::LINE_8);
  } else {
    p.footprint(cv::Rect(x0, y0, w, h)).setTo(255);
  }
  p.occluder.box = bounding_box(p.footprint);
  if (kind.rfind("patch", 0) != 0) {
    for (auto& c : p.occluder.color) c = uint8_t(rng.integer(0, 255));
    return p;
  }
  // Patch: pixels of a photo that is not one of the targets, from a place that does not
  // overlap the destination, so the pasted content is visibly out of place.
  if (targets.size() >= names.size()) return std::nullopt;  // no other photo to cut from
  std::string source;
  do source = names[rng.index(names.size())];
  while (std::find(targets.begin(), targets.end(), source) != targets.end());
  const Size& s = sizes.at(source);
  if (w > s.width || h > s.height) return std::nullopt;
  const Box dest{x0, y0, x0 + w, y0 + h};
  for (int attempt = 0; attempt < 50; ++attempt) {
    const int sx = rng.integer(0, s.width - w), sy = rng.integer(0, s.height - h);
    if (overlap(dest, {sx, sy, sx + w, sy + h})) continue;
    const Box& b = p.occluder.box;
    p.occluder.source_image = source;
    p.occluder.source_box = {b[0] + sx - x0, b[1] + sy - y0, b[2] + sx - x0, b[3] + sy - y0};
    return p;
  }
  return std::nullopt;
}

// 1–3 occluders whose union covers [min, max] of the image (redrawn until it does), for the
// views `targets` (one track; targets[0] names it in errors).
std::vector<Placed> place_occluders(Random& rng, int W, int H, const OccludeOptions& o,
                                    const std::vector<std::string>& targets, const std::vector<std::string>& names,
                                    const std::map<std::string, Size>& sizes) {
  const double pixels = double(W) * H;
  for (int attempt = 0; attempt < 1000; ++attempt) {
    const int count = rng.integer(1, 3);
    const double target = rng.uniform(o.coverage_min, o.coverage_max);
    std::vector<Placed> placed;
    cv::Mat covered = cv::Mat::zeros(H, W, CV_8U);
    for (int i = 0; i < count; ++i) {
      auto p = place_occluder(rng, W, H, target * pixels / count, targets, names, sizes);
      if (!p) break;
      covered |= p->footprint;
      placed.push_back(std::move(*p));
    }
    const double share = cv::countNonZero(covered) / pixels;
    if (int(placed.size()) == count && share >= o.coverage_min && share <= o.coverage_max) return placed;
  }
  throw OccludeError(targets[0] + ": found no occluders covering " + number_text(o.coverage_min) + "–" +
                     number_text(o.coverage_max) + " of a " + size_text(W, H) + " image");
}

// Paints the occluders in order (later ones on top) into `photo` and returns their union.
cv::Mat paint(PhotoFile& photo, const std::vector<Placed>& placed, const fs::path& images_dir) {
  const int W = photo.image.width, H = photo.image.height, C = photo.image.channels;
  cv::Mat covered = cv::Mat::zeros(H, W, CV_8U);
  for (const Placed& p : placed) {
    const Occluder& o = p.occluder;
    std::optional<PhotoFile> source;
    if (!o.source_image.empty()) source = read_photo(images_dir / o.source_image);
    const int dx = o.source_box[0] - o.box[0], dy = o.source_box[1] - o.box[1];
    for (int y = o.box[1]; y < o.box[3]; ++y)
      for (int x = o.box[0]; x < o.box[2]; ++x) {
        if (!p.footprint.at<uint8_t>(y, x)) continue;
        float* px = &photo.image.pixels[(size_t(y) * W + x) * C];
        for (int c = 0; c < C; ++c) {
          if (source) {
            const int sc = std::min(c, source->image.channels - 1);
            px[c] =
                source->image.pixels[(size_t(y + dy) * source->image.width + (x + dx)) * source->image.channels + sc];
          } else {
            const bool alpha = c == 3 || (C == 2 && c == 1);
            const float grey = (o.color[0] + o.color[1] + o.color[2]) / (3 * 255.0f);
            px[c] = alpha ? 1.0f : C >= 3 ? o.color[c] / 255.0f : grey;  // opaque
          }
        }
      }
    covered |= p.footprint;
  }
  return covered;
}

// ---- The job ----

void check_options(const OccludeOptions& o) {
  if (!(o.fraction >= 0 && o.fraction <= 1))
    throw OccludeError("--fraction must be in [0, 1], got " + number_text(o.fraction));
  if (o.track_length < 1) throw OccludeError("--track must be at least 1, got " + std::to_string(o.track_length));
  if (!(o.coverage_min > 0 && o.coverage_min <= o.coverage_max && o.coverage_max <= 0.6))
    throw OccludeError("coverage must satisfy 0 < --coverage-min <= --coverage-max <= 0.6, got " +
                       number_text(o.coverage_min) + " and " + number_text(o.coverage_max));
}

const char* const kOutputEntries[] = {"images", "sparse", "distractor_masks", "occluders.json"};

void check_output_place(const fs::path& data, const fs::path& out, bool overwrite) {
  std::error_code ec;
  const fs::path rel = fs::weakly_canonical(out, ec).lexically_relative(fs::weakly_canonical(data, ec));
  if (!rel.empty() && *rel.begin() != "..")
    throw OccludeError(out.string() + ": the output folder must not be the input folder " + data.string() +
                       " or inside it");
  for (const char* e : kOutputEntries)
    if (!overwrite && fs::exists(out / e, ec))
      throw OccludeError((out / e).string() +
                         ": the output folder already holds a scene (use --overwrite to replace it)");
}

// Only after the input has been checked, so a bad input never costs the previous output.
void remove_previous_output(const fs::path& out) {
  for (const char* e : kOutputEntries) {
    std::error_code ec;
    fs::remove_all(out / e, ec);
    if (ec) throw OccludeError((out / e).string() + ": cannot remove: " + ec.message());
  }
}

void copy_bytes(const fs::path& from, const fs::path& to) {
  make_dirs(to.parent_path());
  std::error_code ec;
  fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec);
  if (ec) throw OccludeError(to.string() + ": cannot copy " + from.string() + ": " + ec.message());
}

// The chosen tracks: runs of `length` consecutive training views (the last may be shorter),
// round(fraction · #train / length) of them picked from the seed, sorted by first view.
std::vector<std::vector<size_t>> chosen_tracks(const std::vector<size_t>& train, double fraction, int length,
                                               uint64_t seed) {
  std::vector<std::vector<size_t>> runs;
  for (size_t i = 0; i < train.size(); i += size_t(length))
    runs.emplace_back(train.begin() + long(i), train.begin() + long(std::min(i + size_t(length), train.size())));
  Random rng(view_seed(seed, "desplat_occlude: chosen views"));
  for (size_t i = runs.size(); i > 1; --i) std::swap(runs[i - 1], runs[rng.index(i)]);  // Fisher–Yates
  runs.resize(std::min(runs.size(), size_t(std::lround(fraction * double(train.size()) / length))));
  std::sort(runs.begin(), runs.end());
  return runs;
}

const char* role_name(ViewRole r) { return r == ViewRole::Train ? "train" : r == ViewRole::Test ? "test" : "unused"; }

nlohmann::json report_json(const OccludeOptions& o, const fs::path& data, const OccludeReport& report) {
  nlohmann::json views = nlohmann::json::array();
  for (const OccludedView& v : report.views) {
    nlohmann::json j{{"name", v.name}, {"role", role_name(v.role)}};
    if (v.role == ViewRole::Train) {
      j["occluded"] = v.occluded;
      j["covered_fraction"] = v.covered_fraction;
      nlohmann::json list = nlohmann::json::array();
      for (const Occluder& oc : v.occluders) {
        nlohmann::json e{{"kind", oc.kind}, {"box", oc.box}};
        if (oc.source_image.empty()) {
          e["color"] = oc.color;
        } else {
          e["source_image"] = oc.source_image;
          e["source_box"] = oc.source_box;
        }
        list.push_back(e);
      }
      j["occluders"] = list;
    }
    views.push_back(j);
  }
  return {{"data", data.string()},
          {"seed", o.seed},
          {"fraction", o.fraction},
          {"coverage", {o.coverage_min, o.coverage_max}},
          {"track_length", o.track_length},
          {"box_convention", "[x0, y0, x1, y1) pixels"},
          {"views", views}};
}

// The input capture: registered names (sorted), their roles, and their photos' sizes.
struct Capture {
  fs::path images, sparse;
  std::vector<std::string> names;
  std::vector<ViewRole> roles;
  std::map<std::string, Size> sizes;
};

Capture read_capture(const fs::path& data, const SplitOptions& split) {
  Capture c{data / "images", data / "sparse" / "0", {}, {}, {}};
  std::error_code ec;
  if (!fs::is_directory(data, ec)) throw OccludeError(data.string() + ": missing scene folder");
  if (!fs::is_directory(c.images, ec)) throw OccludeError(c.images.string() + ": missing images/ folder");
  if (!fs::is_directory(c.sparse, ec)) throw OccludeError(c.sparse.string() + ": missing sparse/0/ folder");
  colmap::Model model;
  try {
    model = colmap::read_model(c.sparse);
    for (const auto& [id, image] : model.images) c.names.push_back(image.name);
    std::sort(c.names.begin(), c.names.end());
    c.roles = assign_split(c.names, split);
  } catch (const std::exception& e) {  // ColmapError and SplitError name the file and problem
    throw OccludeError(e.what());
  }
  if (c.names.size() < 2) throw OccludeError(c.sparse.string() + ": need at least two registered images");
  for (const auto& [id, image] : model.images) {
    const fs::path path = c.images / image.name;
    if (!fs::is_regular_file(path, ec))
      throw OccludeError(path.string() + ": no file for registered image '" + image.name + "'");
    const Size s = read_size(path);
    const colmap::Camera& cam = model.cameras.at(image.camera_id);
    if (uint64_t(s.width) != cam.width || uint64_t(s.height) != cam.height)
      throw OccludeError(path.string() + ": image is " + size_text(s.width, s.height) +
                         " px but its COLMAP camera is " + size_text(int(cam.width), int(cam.height)) + " px");
    c.sizes[image.name] = s;
  }
  return c;
}

// Writes the view's image (a byte copy unless occluded) and, for a training view, its mask.
// `track` is the run of views the view shares its occluders with (empty: not occluded).
OccludedView write_view(const Capture& c, size_t i, const std::vector<size_t>& track, const OccludeOptions& o,
                        const fs::path& out) {
  const std::string& name = c.names[i];
  const bool occlude = !track.empty();
  OccludedView v{name, c.roles[i], occlude, 0, {}};
  const Size s = c.sizes.at(name);
  cv::Mat mask = cv::Mat::zeros(s.height, s.width, CV_8U);
  if (occlude) {
    if (s.width < 16 || s.height < 16)
      throw OccludeError((c.images / name).string() + ": image is " + size_text(s.width, s.height) +
                         " px, too small for occluders (16x16 at least)");
    // Seeded by the track's first view: the same draws, so the same occluders, in every view of it.
    std::vector<std::string> targets;
    for (size_t t : track) targets.push_back(c.names[t]);
    Random rng(view_seed(o.seed, targets[0]));
    const std::vector<Placed> placed = place_occluders(rng, s.width, s.height, o, targets, c.names, c.sizes);
    PhotoFile photo = read_photo(c.images / name);
    mask = paint(photo, placed, c.images);
    make_dirs((out / "images" / name).parent_path());
    write_photo(out / "images" / name, photo);
    for (const Placed& p : placed) v.occluders.push_back(p.occluder);
    v.covered_fraction = cv::countNonZero(mask) / (double(s.width) * s.height);
  } else {
    copy_bytes(c.images / name, out / "images" / name);
  }
  if (v.role == ViewRole::Train) write_mask(distractor_mask_path(out, name), mask);
  return v;
}

}  // namespace

OccludeReport occlude_scene(const OccludeOptions& o) {
  check_options(o);
  if (o.out_dir.empty()) throw OccludeError("--out is empty: give the folder to write the scene into");
  const fs::path data = fs::absolute(o.data_dir).lexically_normal();
  const fs::path out = fs::absolute(o.out_dir).lexically_normal();
  const Capture c = read_capture(data, o.split);
  check_output_place(data, out, o.overwrite);
  try {  // what check_output_place leaves: the root, a file, an --out holding the input
    check_output_folder("--out", o.out_dir, {{"--data", o.data_dir}});
  } catch (const std::invalid_argument& e) {
    throw OccludeError(e.what());
  }

  std::vector<size_t> train;
  for (size_t i = 0; i < c.names.size(); ++i)
    if (c.roles[i] == ViewRole::Train) train.push_back(i);
  std::map<size_t, std::vector<size_t>> track_of;  // occluded view -> its track
  for (const std::vector<size_t>& track : chosen_tracks(train, o.fraction, o.track_length, o.seed))
    for (size_t i : track) track_of[i] = track;
  remove_previous_output(out);  // nothing there unless overwrite (check_output_place)

  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(c.sparse, ec))
    if (entry.is_regular_file()) copy_bytes(entry.path(), out / "sparse" / "0" / entry.path().filename());
  if (ec) throw OccludeError(c.sparse.string() + ": cannot list: " + ec.message());

  OccludeReport report;
  for (size_t i = 0; i < c.names.size(); ++i) {
    const auto it = track_of.find(i);
    report.views.push_back(write_view(c, i, it == track_of.end() ? std::vector<size_t>{} : it->second, o, out));
  }

  const fs::path json_path = out / "occluders.json";
  std::ofstream json(json_path);
  json << report_json(o, data, report).dump(2) << "\n";
  if (!json.flush()) throw OccludeError(json_path.string() + ": cannot write");
  return report;
}

}  // namespace desplat
