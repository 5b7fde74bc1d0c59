// One table of (name, field) pairs drives both directions, so a new setting is added
// in exactly one place.
#include "desplat/train/train_config_json.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <string>
#include <variant>

namespace desplat {

// The action is written and read as its name; an unknown name is an error naming the setting.
void to_json(nlohmann::json& j, const TransientPointAction& a) { j = to_string(a); }
void from_json(const nlohmann::json& j, TransientPointAction& a) {
  if (!j.is_string()) throw std::invalid_argument("config: init.transient_points must be a string (keep, drop or seed)");
  a = transient_point_action_from_string(j.get<std::string>());
}

// The pixel loops' instruction set, by name (raster.hpp, KernelIsa).
void to_json(nlohmann::json& j, const KernelIsa& isa) { j = kernel_isa_name(isa); }
void from_json(const nlohmann::json& j, KernelIsa& isa) {
  const auto parsed = j.is_string() ? parse_kernel_isa(j.get<std::string>()) : std::nullopt;
  if (!parsed) throw std::invalid_argument("config: kernel_isa must be auto, portable, avx2 or avx512 (got " + j.dump() + ")");
  isa = *parsed;
}

namespace {

using Field = std::variant<int*, int64_t*, float*, bool*, uint64_t*, std::array<float, 3>*, TransientPointAction*,
                           KernelIsa*>;
struct Entry {
  const char* name;
  Field field;
};

std::vector<Entry> fields(TrainConfig& c) {
  return {
      {"iterations", &c.iterations},
      {"batch", &c.batch},
      {"sh_degree", &c.sh_degree},
      {"sh_degree_interval", &c.sh_degree_interval},
      {"num_downscales", &c.num_downscales},
      {"resolution_schedule", &c.resolution_schedule},
      {"ssim_lambda", &c.ssim_lambda},
      {"means_lr_final", &c.means_lr_final},
      {"means_lr_decay_steps", &c.means_lr_decay_steps},
      {"lr.means", &c.lr.means},
      {"lr.log_scales", &c.lr.log_scales},
      {"lr.quats", &c.lr.quats},
      {"lr.opacity_logits", &c.lr.opacity_logits},
      {"lr.sh_dc", &c.lr.colors_dc},
      {"lr.sh_rest", &c.lr.colors_rest},
      {"densify.enabled", &c.densify.enabled},
      {"densify.warmup", &c.densify.warmup},
      {"densify.refine_every", &c.densify.refine_every},
      {"densify.reset_alpha_every", &c.densify.reset_alpha_every},
      {"densify.stop_split_at", &c.densify.stop_split_at},
      {"densify.stop_screen_size_at", &c.densify.stop_screen_size_at},
      {"densify.grad_threshold", &c.densify.grad_threshold},
      {"densify.size_threshold", &c.densify.size_threshold},
      {"densify.split_screen_size", &c.densify.split_screen_size},
      {"densify.split_samples", &c.densify.split_samples},
      {"densify.split_scale_factor", &c.densify.split_scale_factor},
      {"densify.cull_alpha", &c.densify.cull_alpha},
      {"densify.cull_scale", &c.densify.cull_scale},
      {"densify.cull_screen_size", &c.densify.cull_screen_size},
      {"densify.normalize_each_step", &c.densify.stats.normalize_each_step},
      {"densify.visible_count_from_one", &c.densify.stats.visible_count_from_one},
      {"densify.radius_from_eigenvalue", &c.densify.stats.radius_from_eigenvalue},
      {"densify.hide_behind_distractors", &c.densify.stats.hide_behind_distractors},
      {"densify.gradient_per_seen_pixel", &c.densify.stats.gradient_per_seen_pixel},
      {"densify.split_screen_needs_grad", &c.densify.split_screen_needs_grad},
      {"densify.inherit_moments", &c.densify.inherit_moments},
      {"densify.camera_path_radius", &c.densify.camera_path.radius},
      {"densify.camera_path_max_segment", &c.densify.camera_path.max_segment},
      {"densify.camera_path_by_extent", &c.densify.camera_path.by_extent},
      {"densify.camera_path_blind_gap", &c.densify.camera_path.blind_gap},
      {"distractors.enabled", &c.distractors.enabled},
      {"distractors.initial_count", &c.distractors.initial_count},
      {"distractors.reference_pixels", &c.distractors.reference_pixels},
      {"distractors.init_depth", &c.distractors.init_depth},
      {"distractors.init_half_width", &c.distractors.init_half_width},
      {"distractors.init_opacity", &c.distractors.init_opacity},
      {"distractors.lr.means", &c.distractors.lr.means},
      {"distractors.lr.log_scales", &c.distractors.lr.log_scales},
      {"distractors.lr.quats", &c.distractors.lr.quats},
      {"distractors.lr.opacity_logits", &c.distractors.lr.opacity_logits},
      {"distractors.lr.rgb", &c.distractors.lr.colors_dc},
      {"distractors.density_control", &c.distractors.density_control},
      {"distractors.refine_every_epochs", &c.distractors.refine_every_epochs},
      {"distractors.regularize", &c.distractors.regularize},
      {"distractors.lambda_static", &c.distractors.lambda_static},
      {"distractors.lambda_distractor", &c.distractors.lambda_distractor},
      {"distractors.lambda_mask_tv", &c.distractors.lambda_mask_tv},
      {"distractors.lambda_occluder_colour", &c.distractors.lambda_occluder_colour},
      {"distractors.explained_tolerance", &c.distractors.explained_tolerance},
      {"distractors.lambda_explained", &c.distractors.lambda_explained},
      {"distractors.lambda_owned", &c.distractors.lambda_owned},
      {"distractors.pixels_per_distractor", &c.distractors.pixels_per_distractor},
      {"distractors.count_connected_misses", &c.distractors.count_connected_misses},
      {"distractors.size_threshold_at_scene_depth", &c.distractors.size_threshold_at_scene_depth},
      {"distractors.reseed_starved_views", &c.distractors.reseed_starved_views},
      {"distractors.seed_uncovered", &c.distractors.seed_uncovered},
      {"distractors.seed_waits_after_reset", &c.distractors.seed_waits_after_reset},
      {"distractors.grow_after", &c.distractors.grow_after},
      {"distractors.owned_after", &c.distractors.owned_after},
      {"distractors.seed_after", &c.distractors.seed_after},
      {"distractors.min_blend_weight", &c.distractors.min_blend_weight},
      {"distractors.max_alpha_sum", &c.distractors.max_alpha_sum},
      {"appearance.enabled", &c.appearance.enabled},
      {"appearance.image_dim", &c.appearance.image_dim},
      {"appearance.fourier_frequencies", &c.appearance.fourier_frequencies},
      {"appearance.hidden_width", &c.appearance.hidden_width},
      {"appearance.hidden_layers", &c.appearance.hidden_layers},
      {"appearance.lr.mlp", &c.appearance.lr_mlp},
      {"appearance.lr.image_embeddings", &c.appearance.lr_image},
      {"appearance.lr.gaussian_embeddings", &c.lr.features},
      {"appearance.test_steps", &c.appearance.test_steps},
      {"appearance.test_lr", &c.appearance.test_lr},
      {"appearance.test_start_from_best_look", &c.appearance.test_start_from_best_look},
      {"background.enabled", &c.background.enabled},
      {"background.image_dim", &c.background.image_dim},
      {"background.share_appearance_embedding", &c.background.share_appearance_embedding},
      {"background.opaque_off_for_steady_sky", &c.background.opaque_off_for_steady_sky},
      {"background.hidden_width", &c.background.hidden_width},
      {"background.hidden_layers", &c.background.hidden_layers},
      {"background.sh_degree", &c.background.sh_degree},
      {"background.sh_degree_interval", &c.background.sh_degree_interval},
      {"background.lr.mlp", &c.background.lr_mlp},
      {"background.lr.sh_rest", &c.background.lr_rest},
      {"background.lr.image_embeddings", &c.background.lr_image},
      {"background.lambda_alpha", &c.background.lambda_alpha},
      {"background.lambda_opaque", &c.background.lambda_opaque},
      {"background.explained_error", &c.background.explained_error},
      {"background.explained_share", &c.background.explained_share},
      {"init.transient_points", &c.transient_points.action},
      {"init.transient_min_track_images", &c.transient_points.min_track_images},
      {"init.transient_color_tolerance", &c.transient_points.color_tolerance},
      {"init.transient_per_view_gain", &c.transient_points.per_view_gain},
      {"selective_adam", &c.selective_adam},
      {"kernel_isa", &c.kernel_isa},
      {"random_background", &c.random_background},
      {"eval_background", &c.eval_background},
      {"random_init_points", &c.random_init_points},
      {"random_init_extent", &c.random_init_extent},
      {"seed", &c.seed},
      {"threads", &c.threads},
  };
}

nlohmann::json::json_pointer pointer(const std::string& dotted) {
  std::string p = "/" + dotted;
  for (char& ch : p)
    if (ch == '.') ch = '/';
  return nlohmann::json::json_pointer(p);
}

void collect_leaves(const nlohmann::json& j, const std::string& prefix, std::vector<std::string>& out) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string key = prefix.empty() ? it.key() : prefix + "." + it.key();
    if (it->is_object()) collect_leaves(*it, key, out);
    else out.push_back(key);
  }
}

}  // namespace

namespace {

// `value` must be finite and in [lo, hi], or (lo, hi] when lo_open; else one error naming
// the setting, what is allowed and what it got.
void require(const char* name, double value, double lo, double hi, bool lo_open, const char* allowed) {
  if (std::isfinite(value) && value >= lo && value <= hi && !(lo_open && value == lo)) return;
  std::ostringstream got;
  got << value;
  throw std::invalid_argument(std::string("config: ") + name + " must be " + allowed + " (got " + got.str() + ")");
}

constexpr double kBig = 1e18;

}  // namespace

void validate_config(const TrainConfig& c) {
  // Counts and intervals: several are divisors or moduli, so 0 would crash the run.
  require("iterations", double(c.iterations), 1, kBig, false, "at least 1");
  // A batch holds at most one refinement of the schedule (batch_event).
  const int max_batch = std::min(1024, std::max(1, c.densify.refine_every));
  const std::string batch_allowed = "1.." + std::to_string(max_batch) + " (at most densify.refine_every and 1024)";
  require("batch", c.batch, 1, max_batch, false, batch_allowed.c_str());
  require("sh_degree", c.sh_degree, 0, 3, false, "0, 1, 2 or 3");
  require("sh_degree_interval", c.sh_degree_interval, 1, kBig, false, "at least 1");
  require("num_downscales", c.num_downscales, 0, 10, false, "0..10");
  require("resolution_schedule", c.resolution_schedule, 1, kBig, false, "at least 1");
  require("means_lr_decay_steps", double(c.means_lr_decay_steps), 1, kBig, false, "at least 1");
  require("densify.warmup", c.densify.warmup, 0, kBig, false, "≥ 0");
  require("densify.refine_every", c.densify.refine_every, 1, kBig, false, "at least 1");
  require("densify.reset_alpha_every", c.densify.reset_alpha_every, 1, kBig, false, "at least 1");
  require("densify.stop_split_at", c.densify.stop_split_at, 0, kBig, false, "≥ 0");
  require("densify.stop_screen_size_at", c.densify.stop_screen_size_at, 0, kBig, false, "≥ 0");
  require("densify.split_samples", c.densify.split_samples, 1, 64, false, "1..64");
  require("distractors.initial_count", c.distractors.initial_count, 0, 1e7, false, "0..10,000,000");
  require("distractors.reference_pixels", c.distractors.reference_pixels, 0, kBig, false, "≥ 0");
  require("distractors.refine_every_epochs", c.distractors.refine_every_epochs, 1, kBig, false, "at least 1");
  require("distractors.pixels_per_distractor", c.distractors.pixels_per_distractor, 0, kBig, false, "≥ 0");
  require("distractors.grow_after", c.distractors.grow_after, 0, kBig, false, "≥ 0");
  require("distractors.owned_after", c.distractors.owned_after, 0, kBig, false, "≥ 0");
  require("distractors.seed_after", c.distractors.seed_after, 0, kBig, false, "≥ 0");
  require("distractors.min_blend_weight", c.distractors.min_blend_weight, 0, kBig, false, "≥ 0");
  require("distractors.max_alpha_sum", c.distractors.max_alpha_sum, 0, kBig, false, "≥ 0");
  require("appearance.image_dim", c.appearance.image_dim, 1, 4096, false, "1..4096");
  require("appearance.fourier_frequencies", c.appearance.fourier_frequencies, 1, 16, false, "1..16");
  require("appearance.hidden_width", c.appearance.hidden_width, 1, 4096, false, "1..4096");
  require("appearance.hidden_layers", c.appearance.hidden_layers, 1, 16, false, "1..16");
  require("appearance.test_steps", c.appearance.test_steps, 1, 1e6, false, "1..1,000,000");
  require("appearance.test_lr", c.appearance.test_lr, 0, kBig, true, "> 0");
  require("background.image_dim", c.background.image_dim, 1, 4096, false, "1..4096");
  require("background.hidden_width", c.background.hidden_width, 1, 4096, false, "1..4096");
  require("background.hidden_layers", c.background.hidden_layers, 1, 16, false, "1..16");
  require("background.sh_degree", c.background.sh_degree, 0, 4, false, "0..4");
  require("background.sh_degree_interval", c.background.sh_degree_interval, 1, kBig, false, "at least 1");
  require("background.lambda_alpha", c.background.lambda_alpha, 0, kBig, false, "≥ 0");
  require("background.lambda_opaque", c.background.lambda_opaque, 0, kBig, false, "≥ 0");
  require("background.explained_error", c.background.explained_error, 0, kBig, false, "≥ 0");
  require("background.explained_share", c.background.explained_share, 0, 0.999999, false, "in [0, 1)");
  require("init.transient_min_track_images", c.transient_points.min_track_images, 0, kBig, false, "≥ 0");
  require("random_init_points", c.random_init_points, 1, 1e8, false, "1..100,000,000");
  require("threads", c.threads, 0, 4096, false, "0 (all cores) or a positive count");
  if (!cpu_supports(c.kernel_isa))
    throw std::invalid_argument(std::string("config: kernel_isa ") + kernel_isa_name(c.kernel_isa) +
                                " is not supported by this CPU (or this build); use auto");
  // Rates: the means' rate decays on a log scale, so it and its final value must be > 0.
  require("lr.means", c.lr.means, 0, kBig, true, "> 0");
  require("means_lr_final", c.means_lr_final, 0, kBig, true, "> 0");
  const std::pair<const char*, float> rates[] = {
      {"lr.log_scales", c.lr.log_scales}, {"lr.quats", c.lr.quats}, {"lr.opacity_logits", c.lr.opacity_logits},
      {"lr.sh_dc", c.lr.colors_dc}, {"lr.sh_rest", c.lr.colors_rest},
      {"distractors.lr.means", c.distractors.lr.means}, {"distractors.lr.log_scales", c.distractors.lr.log_scales},
      {"distractors.lr.quats", c.distractors.lr.quats},
      {"distractors.lr.opacity_logits", c.distractors.lr.opacity_logits},
      {"distractors.lr.rgb", c.distractors.lr.colors_dc},
      {"appearance.lr.mlp", c.appearance.lr_mlp}, {"appearance.lr.image_embeddings", c.appearance.lr_image},
      {"appearance.lr.gaussian_embeddings", c.lr.features},
      {"background.lr.mlp", c.background.lr_mlp}, {"background.lr.sh_rest", c.background.lr_rest},
      {"background.lr.image_embeddings", c.background.lr_image}};
  for (const auto& [name, rate] : rates) require(name, rate, 0, kBig, false, "≥ 0 (0 freezes the group)");
  // Weights, thresholds and sizes.
  require("ssim_lambda", c.ssim_lambda, 0, 1, false, "in [0, 1]");
  require("densify.grad_threshold", c.densify.grad_threshold, 0, kBig, true, "> 0");
  require("densify.size_threshold", c.densify.size_threshold, 0, kBig, true, "> 0");
  require("densify.split_screen_size", c.densify.split_screen_size, 0, kBig, true, "> 0");
  require("densify.split_scale_factor", c.densify.split_scale_factor, 0, kBig, true, "> 0");
  require("densify.cull_alpha", c.densify.cull_alpha, 0, 1, false, "in [0, 1]");
  require("densify.cull_scale", c.densify.cull_scale, 0, kBig, true, "> 0");
  require("densify.cull_screen_size", c.densify.cull_screen_size, 0, kBig, true, "> 0");
  require("densify.camera_path_radius", c.densify.camera_path.radius, 0, kBig, false, "≥ 0 (0 turns the rule off)");
  require("densify.camera_path_max_segment", c.densify.camera_path.max_segment, 0, kBig, true, "> 0");
  require("densify.camera_path_blind_gap", c.densify.camera_path.blind_gap, 0, kBig, false, "≥ 0 (0 turns the rule off)");
  require("distractors.init_depth", c.distractors.init_depth, 0, kBig, true, "> 0");
  require("distractors.init_half_width", c.distractors.init_half_width, 0, kBig, true, "> 0");
  require("distractors.init_opacity", c.distractors.init_opacity, 0, 0.999, true, "in (0, 0.999]");
  require("distractors.lambda_static", c.distractors.lambda_static, 0, kBig, false, "≥ 0");
  require("distractors.lambda_distractor", c.distractors.lambda_distractor, 0, kBig, false, "≥ 0");
  require("distractors.lambda_mask_tv", c.distractors.lambda_mask_tv, 0, kBig, false, "≥ 0");
  require("distractors.lambda_occluder_colour", c.distractors.lambda_occluder_colour, 0, kBig, false, "≥ 0");
  require("distractors.explained_tolerance", c.distractors.explained_tolerance, 0, kBig, true, "> 0");
  require("distractors.lambda_explained", c.distractors.lambda_explained, 0, kBig, false, "≥ 0");
  require("distractors.lambda_owned", c.distractors.lambda_owned, 0, kBig, false, "≥ 0");
  require("init.transient_color_tolerance", c.transient_points.color_tolerance, 0, kBig, false, "≥ 0");
  require("random_init_extent", c.random_init_extent, 0, kBig, true, "> 0");
  for (const float b : c.eval_background) require("eval_background", b, 0, 1, false, "three values in [0, 1]");
}

nlohmann::json config_to_json(const TrainConfig& c) {
  TrainConfig copy = c;
  nlohmann::json j = nlohmann::json::object();
  for (const Entry& e : fields(copy)) std::visit([&](auto* p) { j[pointer(e.name)] = *p; }, e.field);
  return j;
}

std::vector<std::string> config_differences(const TrainConfig& a, const TrainConfig& b, const std::string& b_name,
                                            const std::vector<std::string>& ignore) {
  const nlohmann::json ja = config_to_json(a), jb = config_to_json(b);
  // Settings are float32: 7 significant digits show them as written (0.08, not 0.0799999982).
  auto show = [](const nlohmann::json& v) {
    if (!v.is_number_float()) return v.dump();
    char text[32];
    std::snprintf(text, sizeof text, "%.7g", v.get<double>());
    return std::string(text);
  };
  TrainConfig names_only;
  std::vector<std::string> out;
  for (const Entry& e : fields(names_only)) {
    if (std::find(ignore.begin(), ignore.end(), e.name) != ignore.end()) continue;
    const auto ptr = pointer(e.name);
    if (ja.at(ptr) != jb.at(ptr))
      out.push_back(std::string(e.name) + " " + show(ja.at(ptr)) + " (" + show(jb.at(ptr)) + " in " + b_name + ")");
  }
  return out;
}

std::vector<std::string> settings_absent_from(const nlohmann::json& j) {
  TrainConfig names_only;
  std::vector<std::string> out;
  for (const Entry& e : fields(names_only))
    if (!j.is_object() || !j.contains(pointer(e.name))) out.push_back(e.name);
  return out;
}

TrainConfig config_from_json(const nlohmann::json& j, TrainConfig base) {
  if (!j.is_object()) throw std::invalid_argument("config: the top level must be a JSON object");
  std::vector<std::string> leaves;
  collect_leaves(j, "", leaves);
  auto table = fields(base);
  for (const std::string& key : leaves) {
    bool known = false;
    for (const Entry& e : table) known = known || key == e.name;
    if (!known) throw std::invalid_argument("config: unknown setting '" + key + "'");
  }
  for (const Entry& e : table) {
    const auto ptr = pointer(e.name);
    if (!j.contains(ptr)) continue;
    try {
      std::visit([&](auto* p) { *p = j.at(ptr).get<std::remove_pointer_t<decltype(p)>>(); }, e.field);
    } catch (const nlohmann::json::exception& ex) {
      throw std::invalid_argument(std::string("config: setting '") + e.name + "' has the wrong type (" + ex.what() + ")");
    }
  }
  validate_config(base);
  return base;
}

}  // namespace desplat
