// Scene descriptions: JSON files layered over a base file and the defaults, every key checked
// by name and every value by range, errors naming the file and the key.
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "desplat/io/json_text.hpp"
#include "desplat/synth/synth.hpp"

namespace desplat::synth {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Where a value comes from, for error messages.
struct Source {
  std::string file;
  [[noreturn]] void fail(const std::string& key, const std::string& problem) const {
    throw SynthError(file + ": key '" + key + "': " + problem);
  }
};

std::string shown(const json& v) {
  std::string s = v.dump();
  return s.size() > 60 ? s.substr(0, 57) + "..." : s;
}

std::string join_key(const std::string& prefix, const std::string& key) {
  return prefix.empty() ? key : prefix + "." + key;
}

using Handler = std::function<void(const json& value, const std::string& key)>;

// Calls the handler of every key of `obj`; a key without a handler is an error.
void apply_fields(const json& obj, const std::string& prefix, const Source& src,
                  const std::map<std::string, Handler>& handlers) {
  if (!obj.is_object()) src.fail(prefix, "must be a JSON object, got " + shown(obj));
  for (const auto& [key, value] : obj.items()) {
    const std::string full = join_key(prefix, key);
    const auto it = handlers.find(key);
    if (it == handlers.end()) {
      std::string known;
      for (const auto& h : handlers) known += (known.empty() ? "" : ", ") + h.first;
      src.fail(full, "unknown key (known here: " + known + ")");
    }
    it->second(value, full);
  }
}

// ---- Value readers: each checks type and range ----------------------------------------------

double number(const json& v, const std::string& key, const Source& src, double lo, double hi) {
  if (!v.is_number()) src.fail(key, "must be a number, got " + shown(v));
  const double x = v.get<double>();
  if (!std::isfinite(x) || x < lo || x > hi) {
    std::ostringstream range;
    range << "must be in [" << lo << ", " << hi << "], got " << shown(v);
    src.fail(key, range.str());
  }
  return x;
}

int integer(const json& v, const std::string& key, const Source& src, int lo, int hi) {
  if (!v.is_number_integer()) src.fail(key, "must be an integer, got " + shown(v));
  const int64_t x = v.get<int64_t>();
  if (x < lo || x > hi)
    src.fail(key, "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + shown(v));
  return static_cast<int>(x);
}

bool boolean(const json& v, const std::string& key, const Source& src) {
  if (!v.is_boolean()) src.fail(key, "must be true or false, got " + shown(v));
  return v.get<bool>();
}

std::string one_of(const json& v, const std::string& key, const Source& src, const std::vector<std::string>& names) {
  std::string list;
  for (const auto& n : names) list += (list.empty() ? "\"" : ", \"") + n + "\"";
  if (v.is_string())
    for (const auto& n : names)
      if (v.get<std::string>() == n) return n;
  src.fail(key, "must be one of " + list + ", got " + shown(v));
}

template <size_t N>
std::array<double, N> numbers(const json& v, const std::string& key, const Source& src, double lo, double hi) {
  if (!v.is_array() || v.size() != N)
    src.fail(key, "must be an array of " + std::to_string(N) + " numbers, got " + shown(v));
  std::array<double, N> out{};
  for (size_t i = 0; i < N; ++i) out[i] = number(v[i], key + "[" + std::to_string(i) + "]", src, lo, hi);
  return out;
}

// A [min, max] pair with min ≤ max.
template <class T>
std::array<T, 2> range_pair(const json& v, const std::string& key, const Source& src, double lo, double hi) {
  const auto r = numbers<2>(v, key, src, lo, hi);
  if (r[0] > r[1]) src.fail(key, "must be [min, max] with min <= max, got " + shown(v));
  if constexpr (std::is_same_v<T, int>) {
    if (!v[0].is_number_integer() || !v[1].is_number_integer()) src.fail(key, "must hold integers, got " + shown(v));
    return {static_cast<int>(r[0]), static_cast<int>(r[1])};
  } else {
    return r;
  }
}

constexpr double kBig = 1e6;  // bound for coordinates and sizes: catches typos, not real scenes

Rgb color(const json& v, const std::string& key, const Source& src) { return numbers<3>(v, key, src, 0, 1); }
Vec3d coords(const json& v, const std::string& key, const Source& src) { return numbers<3>(v, key, src, -kBig, kBig); }

// ---- Sections --------------------------------------------------------------------------------

void apply_texture(TextureSpec& t, const json& j, const std::string& prefix, const Source& s) {
  apply_fields(j, prefix, s,
               {{"kind",
                 [&](const json& v, const std::string& k) {
                   t.kind = one_of(v, k, s, {"solid", "checker", "stripes", "noise"});
                 }},
                {"color_a", [&](const json& v, const std::string& k) { t.color_a = color(v, k, s); }},
                {"color_b", [&](const json& v, const std::string& k) { t.color_b = color(v, k, s); }},
                {"scale", [&](const json& v, const std::string& k) { t.scale = number(v, k, s, 1e-3, 1e3); }},
                {"detail", [&](const json& v, const std::string& k) { t.detail = number(v, k, s, 0, 1); }}});
}

ObjectSpec parse_object(const json& j, const std::string& prefix, const Source& s) {
  ObjectSpec o;
  apply_fields(j, prefix, s,
               {{"shape",
                 [&](const json& v, const std::string& k) {
                   o.shape = one_of(v, k, s, {"plane", "box", "sphere"});
                 }},
                {"center", [&](const json& v, const std::string& k) { o.center = coords(v, k, s); }},
                {"size", [&](const json& v, const std::string& k) { o.size = numbers<3>(v, k, s, 0, kBig); }},
                {"radius", [&](const json& v, const std::string& k) { o.radius = number(v, k, s, 1e-6, kBig); }},
                {"normal", [&](const json& v, const std::string& k) { o.normal = coords(v, k, s); }},
                {"yaw_deg", [&](const json& v, const std::string& k) { o.yaw_deg = number(v, k, s, -360, 360); }},
                {"texture", [&](const json& v, const std::string& k) { apply_texture(o.texture, v, k, s); }}});
  const double n2 = o.normal[0] * o.normal[0] + o.normal[1] * o.normal[1] + o.normal[2] * o.normal[2];
  if (o.shape == "plane" && n2 < 1e-12) s.fail(prefix + ".normal", "must not be zero");
  const bool flat_box = o.shape == "box" && (o.size[0] <= 0 || o.size[1] <= 0 || o.size[2] <= 0);
  if (flat_box || (o.shape == "plane" && (o.size[0] <= 0 || o.size[1] <= 0)))
    s.fail(prefix + ".size", "a " + o.shape + " needs positive extents, got " + shown(j.value("size", json())));
  return o;
}

void apply_world(WorldSpec& w, const json& j, const std::string& prefix, const Source& s) {
  apply_fields(
      j, prefix, s,
      {{"objects",
        [&](const json& v, const std::string& k) {
          if (!v.is_array() || v.empty()) s.fail(k, "must be a non-empty array of objects, got " + shown(v));
          w.objects.clear();
          for (size_t i = 0; i < v.size(); ++i)
            w.objects.push_back(parse_object(v[i], k + "[" + std::to_string(i) + "]", s));
        }},
       {"light",
        [&](const json& v, const std::string& k) {
          apply_fields(
              v, k, s,
              {{"direction", [&](const json& x, const std::string& kk) { w.light.direction = coords(x, kk, s); }},
               {"ambient", [&](const json& x, const std::string& kk) { w.light.ambient = number(x, kk, s, 0, 1); }}});
        }},
       {"background", [&](const json& v, const std::string& k) { w.background = color(v, k, s); }}});
}

void apply_camera(CameraSpec& c, const json& j, const std::string& prefix, const Source& s) {
  apply_fields(
      j, prefix, s,
      {{"width", [&](const json& v, const std::string& k) { c.width = integer(v, k, s, 8, 8192); }},
       {"height", [&](const json& v, const std::string& k) { c.height = integer(v, k, s, 8, 8192); }},
       {"fov_x_deg", [&](const json& v, const std::string& k) { c.fov_x_deg = number(v, k, s, 5, 150); }},
       {"principal_offset_px",
        [&](const json& v, const std::string& k) { c.principal_offset_px = numbers<2>(v, k, s, -kBig, kBig); }},
       {"model",
        [&](const json& v, const std::string& k) {
          c.model = one_of(v, k, s, {"PINHOLE", "OPENCV"});
        }},
       {"distortion", [&](const json& v, const std::string& k) { c.distortion = numbers<4>(v, k, s, -1, 1); }}});
}

void apply_views(ViewsSpec& w, const json& j, const std::string& prefix, const Source& s) {
  apply_fields(j, prefix, s,
               {{"count", [&](const json& v, const std::string& k) { w.count = integer(v, k, s, 2, 9999); }},
                {"path",
                 [&](const json& v, const std::string& k) {
                   w.path = one_of(v, k, s, {"orbit", "forward", "walk"});
                 }},
                {"target", [&](const json& v, const std::string& k) { w.target = coords(v, k, s); }},
                {"radius", [&](const json& v, const std::string& k) { w.radius = number(v, k, s, 1e-3, kBig); }},
                {"height", [&](const json& v, const std::string& k) { w.height = number(v, k, s, -kBig, kBig); }},
                {"arc_deg", [&](const json& v, const std::string& k) { w.arc_deg = number(v, k, s, 0, 360); }},
                {"start_deg", [&](const json& v, const std::string& k) { w.start_deg = number(v, k, s, -360, 360); }},
                {"spread", [&](const json& v, const std::string& k) { w.spread = numbers<2>(v, k, s, 0, kBig); }},
                {"position_jitter",
                 [&](const json& v, const std::string& k) { w.position_jitter = number(v, k, s, 0, kBig); }}});
}

void apply_effects(Description& d, const std::string& section, const json& j, const Source& s) {
  if (section == "sky") {
    auto& y = d.sky;
    apply_fields(j, section, s,
                 {{"enabled", [&](const json& v, const std::string& k) { y.enabled = boolean(v, k, s); }},
                  {"horizon", [&](const json& v, const std::string& k) { y.horizon = color(v, k, s); }},
                  {"zenith", [&](const json& v, const std::string& k) { y.zenith = color(v, k, s); }},
                  {"clouds", [&](const json& v, const std::string& k) { y.clouds = number(v, k, s, 0, 1); }}});
  } else if (section == "distractors") {
    auto& x = d.distractors;
    apply_fields(
        j, section, s,
        {{"clutter_ratio", [&](const json& v, const std::string& k) { x.clutter_ratio = number(v, k, s, 0, 1); }},
         {"per_view", [&](const json& v, const std::string& k) { x.per_view = range_pair<int>(v, k, s, 1, 64); }},
         {"size", [&](const json& v, const std::string& k) { x.size = range_pair<double>(v, k, s, 0.01, 2); }},
         {"depth", [&](const json& v, const std::string& k) { x.depth = range_pair<double>(v, k, s, 0.01, 0.95); }},
         {"track_length", [&](const json& v, const std::string& k) { x.track_length = integer(v, k, s, 1, 1000); }}});
  } else if (section == "exposure") {
    auto& e = d.exposure;
    apply_fields(
        j, section, s,
        {{"stops", [&](const json& v, const std::string& k) { e.stops = number(v, k, s, 0, 4); }},
         {"white_balance", [&](const json& v, const std::string& k) { e.white_balance = number(v, k, s, 0, 0.9); }},
         {"test_views", [&](const json& v, const std::string& k) { e.test_views = boolean(v, k, s); }}});
  } else if (section == "noise") {
    auto& n = d.noise;
    apply_fields(j, section, s,
                 {{"sigma", [&](const json& v, const std::string& k) { n.sigma = number(v, k, s, 0, 1); }},
                  {"shot", [&](const json& v, const std::string& k) { n.shot = number(v, k, s, 0, 1); }},
                  {"test_views", [&](const json& v, const std::string& k) { n.test_views = boolean(v, k, s); }}});
  } else {  // points
    auto& p = d.points;
    apply_fields(
        j, section, s,
        {{"count", [&](const json& v, const std::string& k) { p.count = integer(v, k, s, 0, 10'000'000); }},
         {"position_noise_px",
          [&](const json& v, const std::string& k) { p.position_noise_px = number(v, k, s, 0, 100); }},
         {"observation_noise_px",
          [&](const json& v, const std::string& k) { p.observation_noise_px = number(v, k, s, 0, 100); }},
         {"min_track", [&](const json& v, const std::string& k) { p.min_track = integer(v, k, s, 1, 9999); }}});
  }
}

// {"a.b": 1} -> {"a": {"b": 1}}, recursively, merging with keys already present.
json expand_dotted(const json& j, const std::string& prefix, const Source& src) {
  if (!j.is_object()) return j;
  json out = json::object();
  for (const auto& [key, value] : j.items()) {
    const size_t dot = key.find('.');
    const std::string head = dot == std::string::npos ? key : key.substr(0, dot);
    if (head.empty() || (dot != std::string::npos && dot + 1 == key.size()))
      src.fail(join_key(prefix, key), "malformed dotted key");
    json inner = dot == std::string::npos ? expand_dotted(value, join_key(prefix, key), src)
                                          : expand_dotted(json{{key.substr(dot + 1), value}}, prefix, src);
    json& slot = out[head];
    if (slot.is_null()) {
      slot = std::move(inner);
    } else if (slot.is_object() && inner.is_object()) {
      for (auto& [k, v] : inner.items()) {
        if (slot.contains(k)) src.fail(join_key(join_key(prefix, head), k), "is set twice");
        slot[k] = v;
      }
    } else {
      src.fail(join_key(prefix, head), "is set twice");
    }
  }
  return out;
}

// Checks across fields, after every layer has been applied.
void check_description(const Description& d, const Source& s) {
  if (std::abs(d.camera.principal_offset_px[0]) > d.camera.width / 2.0 ||
      std::abs(d.camera.principal_offset_px[1]) > d.camera.height / 2.0)
    s.fail("camera.principal_offset_px", "moves the principal point outside the image");
  if (d.camera.model == "PINHOLE" && d.camera.distortion != std::array<double, 4>{0, 0, 0, 0})
    s.fail("camera.distortion", "needs \"camera.model\": \"OPENCV\" (PINHOLE has no distortion)");
  if (d.views.path == "orbit" && d.views.radius <= 0) s.fail("views.radius", "must be positive");
  const int num_train = d.views.count - (d.views.count + 7) / 8;
  if (num_train < 1) s.fail("views.count", "leaves no training view");
  if (d.points.min_track > d.views.count)
    s.fail("points.min_track", "exceeds views.count (" + std::to_string(d.views.count) + ")");
}

void apply_layer(Description& d, const json& raw, const Source& s) {
  const json j = expand_dotted(raw, "", s);
  apply_fields(
      j, "", s,
      {{"base", [&](const json&, const std::string& k) { s.fail(k, "is only allowed at the top of a file"); }},
       {"seed",
        [&](const json& v, const std::string& k) {
          if (!v.is_number_unsigned()) s.fail(k, "must be a non-negative integer, got " + shown(v));
          d.seed = v.get<uint64_t>();
        }},
       {"camera", [&](const json& v, const std::string& k) { apply_camera(d.camera, v, k, s); }},
       {"views", [&](const json& v, const std::string& k) { apply_views(d.views, v, k, s); }},
       {"supersampling", [&](const json& v, const std::string& k) { d.supersampling = integer(v, k, s, 1, 4); }},
       {"world", [&](const json& v, const std::string& k) { apply_world(d.world, v, k, s); }},
       {"sky", [&](const json& v, const std::string& k) { apply_effects(d, k, v, s); }},
       {"distractors", [&](const json& v, const std::string& k) { apply_effects(d, k, v, s); }},
       {"exposure", [&](const json& v, const std::string& k) { apply_effects(d, k, v, s); }},
       {"noise", [&](const json& v, const std::string& k) { apply_effects(d, k, v, s); }},
       {"points", [&](const json& v, const std::string& k) { apply_effects(d, k, v, s); }}});
}

json read_json_file(const fs::path& file) {
  std::ifstream in(file);
  if (!in) throw SynthError(file.string() + ": cannot read the scene description");
  try {
    return parse_json_bounded(in, file.string(), /*ignore_comments=*/true);
  } catch (const json::parse_error& e) {
    throw SynthError(file.string() + ": not valid JSON: " + e.what());
  }
}

// The description of `file` with its base chain applied, not yet checked across fields.
Description load_layers(const fs::path& file, std::set<fs::path>& seen) {
  std::error_code ec;  // a pipe (/dev/fd/N) has no canonical path: its absolute one names it
  fs::path canonical = fs::weakly_canonical(file, ec);
  if (ec) canonical = fs::absolute(file);
  if (!seen.insert(canonical).second) throw SynthError(file.string() + ": the chain of \"base\" files loops back here");
  json j = read_json_file(file);
  const Source src{file.string()};
  if (!j.is_object()) throw SynthError(file.string() + ": a scene description must be a JSON object");
  Description d;
  if (j.contains("base")) {
    if (!j["base"].is_string() || j["base"].get<std::string>().empty())
      src.fail("base", "must be a file name, got " + shown(j["base"]));
    const fs::path base = file.parent_path() / j["base"].get<std::string>();
    if (!fs::exists(base)) src.fail("base", "base description " + base.string() + " does not exist");
    d = load_layers(base, seen);
    j.erase("base");
  }
  apply_layer(d, j, src);
  return d;
}

json rgb_json(const Rgb& c) { return json::array({c[0], c[1], c[2]}); }

}  // namespace

std::vector<ObjectSpec> default_world_objects() {
  ObjectSpec ground{
      "plane", {0, 0, 0}, {8, 8, 0}, 0.5, {0, 0, 1}, 0, {"checker", {0.75, 0.7, 0.6}, {0.35, 0.3, 0.28}, 2, 0.4}};
  ObjectSpec box1{"box",
                  {-0.6, -0.3, 0.4},
                  {0.8, 0.8, 0.8},
                  0.5,
                  {0, 0, 1},
                  25,
                  {"noise", {0.8, 0.35, 0.2}, {0.3, 0.1, 0.05}, 6, 0.3}};
  ObjectSpec box2{"box",
                  {0.7, 0.6, 0.25},
                  {1.0, 0.5, 0.5},
                  0.5,
                  {0, 0, 1},
                  -15,
                  {"stripes", {0.2, 0.45, 0.75}, {0.85, 0.85, 0.8}, 5, 0.3}};
  ObjectSpec ball{"sphere",
                  {0.5, -0.7, 0.45},
                  {1, 1, 1},
                  0.45,
                  {0, 0, 1},
                  0,
                  {"noise", {0.3, 0.7, 0.35}, {0.9, 0.85, 0.3}, 5, 0.4}};
  return {ground, box1, box2, ball};
}

Description load_description(const fs::path& file) {
  std::set<fs::path> seen;
  Description d = load_layers(file, seen);
  check_description(d, Source{file.string()});
  return d;
}

Description apply_description(const Description& base, const json& patch, const std::string& source) {
  Description d = base;
  apply_layer(d, patch, Source{source});
  check_description(d, Source{source});
  return d;
}

json description_to_json(const Description& d) {
  json objects = json::array();
  for (const auto& o : d.world.objects) {
    const auto& t = o.texture;
    objects.push_back({{"shape", o.shape},
                       {"center", o.center},
                       {"size", o.size},
                       {"radius", o.radius},
                       {"normal", o.normal},
                       {"yaw_deg", o.yaw_deg},
                       {"texture",
                        {{"kind", t.kind},
                         {"color_a", rgb_json(t.color_a)},
                         {"color_b", rgb_json(t.color_b)},
                         {"scale", t.scale},
                         {"detail", t.detail}}}});
  }
  const auto& c = d.camera;
  const auto& v = d.views;
  return {{"seed", d.seed},
          {"camera",
           {{"width", c.width},
            {"height", c.height},
            {"fov_x_deg", c.fov_x_deg},
            {"principal_offset_px", c.principal_offset_px},
            {"model", c.model},
            {"distortion", c.distortion}}},
          {"views",
           {{"count", v.count},
            {"path", v.path},
            {"target", v.target},
            {"radius", v.radius},
            {"height", v.height},
            {"arc_deg", v.arc_deg},
            {"start_deg", v.start_deg},
            {"spread", v.spread},
            {"position_jitter", v.position_jitter}}},
          {"supersampling", d.supersampling},
          {"world",
           {{"objects", objects},
            {"light", {{"direction", d.world.light.direction}, {"ambient", d.world.light.ambient}}},
            {"background", rgb_json(d.world.background)}}},
          {"sky",
           {{"enabled", d.sky.enabled},
            {"horizon", rgb_json(d.sky.horizon)},
            {"zenith", rgb_json(d.sky.zenith)},
            {"clouds", d.sky.clouds}}},
          {"distractors",
           {{"clutter_ratio", d.distractors.clutter_ratio},
            {"per_view", d.distractors.per_view},
            {"size", d.distractors.size},
            {"depth", d.distractors.depth},
            {"track_length", d.distractors.track_length}}},
          {"exposure",
           {{"stops", d.exposure.stops},
            {"white_balance", d.exposure.white_balance},
            {"test_views", d.exposure.test_views}}},
          {"noise", {{"sigma", d.noise.sigma}, {"shot", d.noise.shot}, {"test_views", d.noise.test_views}}},
          {"points",
           {{"count", d.points.count},
            {"position_noise_px", d.points.position_noise_px},
            {"observation_noise_px", d.points.observation_noise_px},
            {"min_track", d.points.min_track}}}};
}

}  // namespace desplat::synth
