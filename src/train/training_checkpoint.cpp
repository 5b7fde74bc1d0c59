// Names of the checkpoint arrays, for a prefix P = "static" or "distractor/<train view index>":
// "P/<group>", "P/adam_m/<group>", "P/adam_v/<group>", "P/stats/<name>"; and
// "trainer/view_order", and per training view (distractors on) "trainer/view_static_unexplained",
// "trainer/view_composite_unexplained", "trainer/view_seed_due". Per-set scalars (Adam step, statistics flag) are in
// the metadata: "adam_step"/"statistics_empty"/"feature_dim" for the static set, and with the appearance model
// "appearance/mlp", "appearance/image_embeddings" and their "appearance/adam_m/…", "…/adam_v/…"
// with metadata "appearance": {"views", "image_dim", "fourier_frequencies", "hidden_width",
// "hidden_layers", "adam_step"}; with the background model the same under "background/…" and
// metadata "background": {"views", "image_dim", "hidden_width", "hidden_layers", "sh_degree",
// "adam_step"}; "distractors": {"views": [names],
// "adam_step": [...], "statistics_empty": [...]} for the per-view sets.
#include "desplat/train/training_checkpoint.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace desplat {
namespace {

std::string distractor_prefix(size_t view) { return "distractor/" + std::to_string(view); }

// Restored state is never trusted: every value read below is checked against what the run can
// use, and a misfit is one CheckpointError naming the file, the field and what to do.
constexpr const char* kDamaged =
    ": the checkpoint is damaged or not this run's; resume from an intact copy, or train "
    "anew with --overwrite";

[[noreturn]] void refuse(const Checkpoint& c, const std::string& what) {
  throw CheckpointError(c.source.string() + ": " + what + kDamaged);
}

// The float array `name` of `shape`, refused unless every element is finite (and, with
// `non_negative`, ≥ 0): one non-finite parameter would spread NaN through every later step.
const std::vector<float>& finite_array(const Checkpoint& c, const std::string& name, const Checkpoint::Shape& shape,
                                       bool non_negative = false) {
  const std::vector<float>& v = c.get<float>(name, shape);
  size_t bad = 0, first = 0;
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i]) || (non_negative && v[i] < 0)) {
      if (bad++ == 0) first = i;
    }
  if (bad)
    refuse(c, "array '" + name + "' holds " + std::to_string(bad) + " value" + (bad == 1 ? "" : "s") + " that are " +
                  (non_negative ? "negative or " : "") + "not finite (NaN or infinity), the first at element " +
                  std::to_string(first));
  return v;
}

// A metadata value (named `field` in messages): an integer in [lo, hi].
int64_t integer_value(const Checkpoint& c, const nlohmann::json& v, const std::string& field, int64_t lo, int64_t hi) {
  const bool integral = v.is_number_integer() && !(v.is_number_unsigned() && v.get<uint64_t>() > uint64_t(INT64_MAX));
  if (!integral) refuse(c, "metadata field '" + field + "' is " + v.dump() + ", not an integer");
  const int64_t x = v.get<int64_t>();
  if (x < lo || x > hi)
    refuse(c, "metadata field '" + field + "' is " + std::to_string(x) + ", outside " + std::to_string(lo) + ".." +
                  std::to_string(hi));
  return x;
}

// Metadata field `key` of the object `parent`, named `field`: an integer in [lo, hi].
int64_t integer_field(const Checkpoint& c, const nlohmann::json& parent, const std::string& key,
                      const std::string& field, int64_t lo, int64_t hi) {
  if (!parent.is_object() || !parent.contains(key)) refuse(c, "the metadata has no field '" + field + "'");
  return integer_value(c, parent.at(key), field, lo, hi);
}

bool bool_value(const Checkpoint& c, const nlohmann::json& v, const std::string& field) {
  if (!v.is_boolean()) refuse(c, "metadata field '" + field + "' is " + v.dump() + ", not true or false");
  return v.get<bool>();
}

bool bool_field(const Checkpoint& c, const nlohmann::json& parent, const std::string& key, const std::string& field) {
  if (!parent.is_object() || !parent.contains(key)) refuse(c, "the metadata has no field '" + field + "'");
  return bool_value(c, parent.at(key), field);
}

// The list of view names under metadata `section` ("appearance", "background", "distractors").
std::vector<std::string> view_names(const Checkpoint& c, const std::string& section) {
  if (!c.metadata.contains(section)) return {};
  const nlohmann::json& s = c.metadata.at(section);
  if (!s.is_object() || !s.contains("views") || !s.at("views").is_array())
    refuse(c, "metadata field '" + section + ".views' is missing or not a list");
  std::vector<std::string> names;
  for (const nlohmann::json& n : s.at("views")) {
    if (!n.is_string()) refuse(c, "metadata field '" + section + ".views' holds " + n.dump() + ", not a view name");
    names.push_back(n.get<std::string>());
  }
  return names;
}

// A step no run reaches (the paper trains 30,000): a larger step is a damaged checkpoint.
constexpr int64_t kMaxCheckpointStep = 1'000'000'000;

// The scene record: every view's name and training size, in the run's order.
nlohmann::json scene_record(const TrainingData& data) {
  auto list = [](const std::vector<TrainView>& views) {
    nlohmann::json out = nlohmann::json::array();
    for (const TrainView& v : views) out.push_back({v.name, v.camera.width, v.camera.height});
    return out;
  };
  return {{"train", list(data.train)}, {"test", list(data.test)}};
}

// What differs between the checkpoint's scene record and this run's scene; empty if nothing.
std::string scene_difference(const nlohmann::json& recorded, const nlohmann::json& run) {
  for (const char* role : {"train", "test"}) {
    const nlohmann::json& a = recorded.contains(role) ? recorded.at(role) : nlohmann::json::array();
    const nlohmann::json& b = run.at(role);
    auto view = [](const nlohmann::json& v) {
      if (!v.is_array() || v.size() != 3) return v.dump();
      std::string text(1, '\'');
      text += v[0].is_string() ? v[0].get<std::string>() : v[0].dump();
      text += "' at " + v[1].dump() + "x" + v[2].dump();
      return text;
    };
    if (!a.is_array()) return std::string("its ") + role + " views are unreadable (" + a.dump() + ")";
    for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
      if (a[i] != b[i])
        return std::string(role) + " view " + std::to_string(i) + " is " + view(a[i]) + " in the checkpoint but " +
               view(b[i]) + " in this run";
    if (a.size() != b.size())
      return "it has " + std::to_string(a.size()) + " " + role + " views, this run " + std::to_string(b.size());
  }
  return {};
}

// The checkpoint belongs to this run's scene (its views, in order and size), or it is refused.
// Checkpoints from before the record are resumed with a warning: their view lists are still
// range-checked, so a misfit cannot crash the run, but another scene cannot be told apart.
void check_scene(const Trainer& trainer, const Checkpoint& c) {
  if (!c.metadata.contains("scene")) {
    std::printf(
        "warning: %s records no scene (it was written by an older desplat), so it cannot be checked to "
        "belong to this one; resuming it as this scene's\n",
        c.source.c_str());
    return;
  }
  const std::string diff = scene_difference(c.metadata.at("scene"), scene_record(trainer.data()));
  if (!diff.empty())
    throw CheckpointError(c.source.string() + ": the checkpoint belongs to another scene or split: " + diff +
                          "; resume with the data, --split and --downscale it was trained with, or train anew with "
                          "--overwrite");
}

// The arrays of a per-image model (AppearanceModel, BackgroundModel): "P/mlp",
// "P/image_embeddings" and their "P/adam_m/…", "P/adam_v/…".
template <class Model>
void put_per_image_model(Checkpoint& c, const std::string& prefix, const Model& m) {
  const uint64_t views = m.views(), dim = uint64_t(m.settings.image_dim), weights = m.mlp.size();
  c.put(prefix + "/mlp", {weights}, m.mlp);
  c.put(prefix + "/adam_m/mlp", {weights}, m.mlp_m);
  c.put(prefix + "/adam_v/mlp", {weights}, m.mlp_v);
  c.put(prefix + "/image_embeddings", {views, dim}, m.image_embeddings);
  c.put(prefix + "/adam_m/image_embeddings", {views, dim}, m.embed_m);
  c.put(prefix + "/adam_v/image_embeddings", {views, dim}, m.embed_v);
}

// `m.settings` must be set (it gives the shapes).
template <class Model>
void get_per_image_model(const Checkpoint& c, const std::string& prefix, size_t views, Model& m) {
  const uint64_t weights = m.mlp_floats(), dim = uint64_t(m.settings.image_dim);
  m.mlp = finite_array(c, prefix + "/mlp", {weights});
  m.mlp_m = finite_array(c, prefix + "/adam_m/mlp", {weights});
  m.mlp_v = finite_array(c, prefix + "/adam_v/mlp", {weights}, true);
  m.image_embeddings = finite_array(c, prefix + "/image_embeddings", {views, dim});
  m.embed_m = finite_array(c, prefix + "/adam_m/image_embeddings", {views, dim});
  m.embed_v = finite_array(c, prefix + "/adam_v/image_embeddings", {views, dim}, true);
  m.adam_step = integer_field(c, c.metadata.at(prefix), "adam_step", prefix + ".adam_step", 0, kMaxCheckpointStep);
}

void put_trainable(Checkpoint& c, const std::string& prefix, const TrainableGaussians& g) {
  const uint64_t n = g.size();
  for (int k = 0; k < kParamGroups; ++k) {
    const uint64_t stride = g.floats_per_gaussian(ParamGroup(k));
    const std::string name = kParamGroupTable[k].name;
    c.put(prefix + "/" + name, {n, stride}, g.param(ParamGroup(k)));
    c.put(prefix + "/adam_m/" + name, {n, stride}, g.adam_m[k]);
    c.put(prefix + "/adam_v/" + name, {n, stride}, g.adam_v[k]);
  }
  c.put(prefix + "/stats/absgrad_sum", {n}, g.absgrad_sum);
  c.put(prefix + "/stats/visible_count", {n}, g.visible_count);
  c.put(prefix + "/stats/max_screen_radius", {n}, g.max_screen_radius);
}

// A group the checkpoint may lack: features, in checkpoints from before the appearance model
// (always of width 0 there).
bool absent_featureless(const Checkpoint& c, const std::string& name, const ParamGroupInfo& info,
                        const GaussianSet& g) {
  return info.id == ParamGroup::Features && g.feature_dim == 0 && !c.contains(name);
}

GaussianSet get_params(const Checkpoint& c, const std::string& prefix, ColorMode mode, int sh_degree, int feature_dim) {
  GaussianSet g;
  g.sh_degree = sh_degree;
  g.color_mode = mode;
  g.feature_dim = feature_dim;
  const CheckpointArray& opacities = c.array(prefix + "/opacity_logits");
  if (opacities.shape().empty())
    refuse(c, "array '" + prefix + "/opacity_logits' is a scalar, not one row per Gaussian");
  const uint64_t n = opacities.shape()[0];
  for (const ParamGroupInfo& info : kParamGroupTable) {
    const std::string name = prefix + "/" + info.name;
    if (absent_featureless(c, name, info, g)) continue;
    g.*info.values = finite_array(c, name, {n, uint64_t(group_width(info, g))});
  }
  return g;
}

void get_trainable(const Checkpoint& c, const std::string& prefix, TrainableGaussians& g) {
  g.params = get_params(c, prefix, g.params.color_mode, g.params.sh_degree, g.params.feature_dim);
  const uint64_t n = g.size();
  for (int k = 0; k < kParamGroups; ++k) {
    const uint64_t stride = g.floats_per_gaussian(ParamGroup(k));
    if (absent_featureless(c, prefix + "/adam_m/" + kParamGroupTable[k].name, kParamGroupTable[k], g.params)) {
      g.adam_m[k].clear(), g.adam_v[k].clear();
      continue;
    }
    g.adam_m[k] = finite_array(c, prefix + "/adam_m/" + kParamGroupTable[k].name, {n, stride});
    g.adam_v[k] = finite_array(c, prefix + "/adam_v/" + kParamGroupTable[k].name, {n, stride}, true);
  }
  g.absgrad_sum = finite_array(c, prefix + "/stats/absgrad_sum", {n}, true);
  g.visible_count = c.get<int32_t>(prefix + "/stats/visible_count", {n});
  for (size_t i = 0; i < g.visible_count.size(); ++i)
    if (g.visible_count[i] < 0)
      refuse(c, "array '" + prefix + "/stats/visible_count' holds " + std::to_string(g.visible_count[i]) +
                    " at element " + std::to_string(i) + ", a negative count");
  g.max_screen_radius = finite_array(c, prefix + "/stats/max_screen_radius", {n}, true);
  g.check_consistent();
}

}  // namespace

Checkpoint make_training_checkpoint(const Trainer& t, const nlohmann::json& extra_metadata) {
  const TrainableGaussians& g = t.gaussians();
  Checkpoint c;
  c.metadata = extra_metadata.is_object() ? extra_metadata : nlohmann::json::object();
  c.metadata["step"] = t.current_step();
  c.metadata["scene"] = scene_record(t.data());
  c.metadata["adam_step"] = g.adam_step;
  c.metadata["statistics_empty"] = g.statistics_empty;
  c.metadata["sh_degree"] = g.params.sh_degree;
  c.metadata["color_mode"] = g.params.color_mode == ColorMode::RGB ? "rgb" : "sh";
  c.metadata["feature_dim"] = g.params.feature_dim;
  const AppearanceModel& look = t.appearance();
  if (t.config().appearance.enabled) {
    nlohmann::json names = nlohmann::json::array();
    for (const TrainView& v : t.data().train) names.push_back(v.name);
    const AppearanceSettings& as = look.settings;
    c.metadata["appearance"] = {{"views", names},
                                {"image_dim", as.image_dim},
                                {"fourier_frequencies", as.fourier_frequencies},
                                {"hidden_width", as.hidden_width},
                                {"hidden_layers", as.hidden_layers},
                                {"adam_step", look.adam_step}};
    put_per_image_model(c, "appearance", look);
  }
  if (t.config().background.enabled) {
    const BackgroundModel& sky = t.background();
    nlohmann::json names = nlohmann::json::array();
    for (const TrainView& v : t.data().train) names.push_back(v.name);
    const BackgroundSettings& bs = sky.settings;
    c.metadata["background"] = {{"views", names},
                                {"image_dim", bs.image_dim},
                                {"hidden_width", bs.hidden_width},
                                {"hidden_layers", bs.hidden_layers},
                                {"sh_degree", bs.sh_degree},
                                {"shares_appearance_embedding", t.shared_embedding()},
                                {"adam_step", sky.adam_step}};
    put_per_image_model(c, "background", sky);
  }
  c.metadata["view_order_pos"] = t.view_order_pos;
  c.metadata["rng"] = save_rng_state(t.rng());
  put_trainable(c, "static", g);
  if (!t.distractors().empty()) {
    nlohmann::json views = nlohmann::json::array(), steps = nlohmann::json::array(), empty = nlohmann::json::array();
    for (size_t v = 0; v < t.distractors().size(); ++v) {
      const TrainableGaussians& d = t.distractors()[v];
      put_trainable(c, distractor_prefix(v), d);
      views.push_back(t.data().train[v].name);
      steps.push_back(d.adam_step);
      empty.push_back(d.statistics_empty);
    }
    c.metadata["distractors"] = {{"views", views}, {"adam_step", steps}, {"statistics_empty", empty}};
    const uint64_t nv = t.distractors().size();
    c.put("trainer/view_static_unexplained", {nv}, t.view_static_unexplained);
    c.put("trainer/view_composite_unexplained", {nv}, t.view_composite_unexplained);
    c.put("trainer/view_seed_due", {nv}, t.view_seed_due);
  }
  c.put("trainer/view_order", {t.view_order.size()}, t.view_order);
  return c;
}

GaussianSet gaussians_from_checkpoint(const Checkpoint& c) {
  auto optional_int = [&](const char* key, int64_t hi) {
    return c.metadata.contains(key) ? int(integer_field(c, c.metadata, key, key, 0, hi)) : 0;
  };
  const int sh_degree = optional_int("sh_degree", 3);
  if (c.metadata.contains("color_mode") && !c.metadata.at("color_mode").is_string())
    refuse(c, "metadata field 'color_mode' is " + c.metadata.at("color_mode").dump() + ", not \"rgb\" or \"sh\"");
  const ColorMode mode =
      c.metadata.value("color_mode", std::string("sh")) == "rgb" ? ColorMode::RGB : ColorMode::SphericalHarmonics;
  return get_params(c, "static", mode, sh_degree, optional_int("feature_dim", 1 << 16));
}

std::vector<std::string> appearance_views_in_checkpoint(const Checkpoint& c) { return view_names(c, "appearance"); }

AppearanceModel appearance_from_checkpoint(const Checkpoint& c) {
  const std::vector<std::string> views = appearance_views_in_checkpoint(c);
  if (views.empty()) throw CheckpointError(c.source.string() + ": the model was trained without appearance");
  const nlohmann::json& m = c.metadata.at("appearance");
  AppearanceSettings s;
  s.enabled = true;
  s.image_dim = int(integer_field(c, m, "image_dim", "appearance.image_dim", 0, 1 << 16));
  s.fourier_frequencies = int(integer_field(c, m, "fourier_frequencies", "appearance.fourier_frequencies", 0, 1 << 16));
  s.hidden_width = int(integer_field(c, m, "hidden_width", "appearance.hidden_width", 0, 1 << 16));
  s.hidden_layers = int(integer_field(c, m, "hidden_layers", "appearance.hidden_layers", 0, 1 << 16));
  AppearanceModel model;
  model.settings = s;
  get_per_image_model(c, "appearance", views.size(), model);
  return model;
}

std::vector<std::string> background_views_in_checkpoint(const Checkpoint& c) { return view_names(c, "background"); }

BackgroundModel background_from_checkpoint(const Checkpoint& c) {
  const std::vector<std::string> views = background_views_in_checkpoint(c);
  if (views.empty()) throw CheckpointError(c.source.string() + ": the model was trained without a background model");
  const nlohmann::json& m = c.metadata.at("background");
  BackgroundSettings s;
  s.enabled = true;
  s.image_dim = int(integer_field(c, m, "image_dim", "background.image_dim", 0, 1 << 16));
  s.hidden_width = int(integer_field(c, m, "hidden_width", "background.hidden_width", 0, 1 << 16));
  s.hidden_layers = int(integer_field(c, m, "hidden_layers", "background.hidden_layers", 0, 1 << 16));
  s.sh_degree = int(integer_field(c, m, "sh_degree", "background.sh_degree", 0, 1 << 16));
  // Absent in models from before the option: those read their own embeddings.
  s.share_appearance_embedding =
      m.contains("shares_appearance_embedding") &&
      bool_field(c, m, "shares_appearance_embedding", "background.shares_appearance_embedding");
  try {
    s.validate();
  } catch (const std::invalid_argument& e) {
    throw CheckpointError(c.source.string() + ": its background model is damaged: " + e.what());
  }
  BackgroundModel model;
  model.settings = s;
  get_per_image_model(c, "background", views.size(), model);
  return model;
}

std::vector<std::string> distractor_views_in_checkpoint(const Checkpoint& c) { return view_names(c, "distractors"); }

GaussianSet distractors_from_checkpoint(const Checkpoint& c, size_t index) {
  return get_params(c, distractor_prefix(index), ColorMode::RGB, 0, 0);
}

void restore_training_checkpoint(Trainer& trainer, const Checkpoint& c) {
  check_scene(trainer, c);
  TrainableGaussians& g = trainer.mutable_gaussians();
  const int sh_degree = int(integer_field(c, c.metadata, "sh_degree", "sh_degree", 0, 3));
  if (sh_degree != g.params.sh_degree)
    throw CheckpointError(c.source.string() + ": checkpoint has SH degree " + std::to_string(sh_degree) +
                          " but the configuration asks for " + std::to_string(g.params.sh_degree));
  const std::vector<std::string> views = distractor_views_in_checkpoint(c);
  std::vector<TrainableGaussians>& distractors = trainer.mutable_distractors();
  if (views.size() != distractors.size())
    throw CheckpointError(c.source.string() + ": checkpoint has distractors for " + std::to_string(views.size()) +
                          " views but this run has " + std::to_string(distractors.size()) +
                          (distractors.empty() ? " (a static-only run): resume with the effects it was trained with, "
                                                 "without --static-only"
                                               : ""));
  for (size_t v = 0; v < views.size(); ++v)
    if (views[v] != trainer.data().train[v].name)
      throw CheckpointError(c.source.string() + ": distractor buffer " + std::to_string(v) + " belongs to view '" +
                            views[v] + "' but this run's training view " + std::to_string(v) + " is '" +
                            trainer.data().train[v].name + "' (another scene or split?)");
  // The appearance model: on in both or off in both, with the same sizes.
  const bool ckpt_look = c.metadata.contains("appearance"), run_look = trainer.config().appearance.enabled;
  if (ckpt_look != run_look)
    throw CheckpointError(c.source.string() + ": the checkpoint was trained " + (ckpt_look ? "with" : "without") +
                          " the appearance model but this run has it " + (run_look ? "on" : "off") +
                          " (--effects must match the run being resumed)");
  if (run_look) {
    AppearanceModel look = appearance_from_checkpoint(c);
    const AppearanceSettings& want = trainer.config().appearance;
    const AppearanceSettings& got = look.settings;
    if (got.image_dim != want.image_dim || got.fourier_frequencies != want.fourier_frequencies ||
        got.hidden_width != want.hidden_width || got.hidden_layers != want.hidden_layers)
      throw CheckpointError(c.source.string() + ": the checkpoint's appearance model has embeddings of " +
                            std::to_string(got.image_dim) + " (image) and " + std::to_string(got.feature_dim()) +
                            " (Gaussian) and " + std::to_string(got.hidden_layers) + " hidden layers of " +
                            std::to_string(got.hidden_width) + "; this run asks for " + std::to_string(want.image_dim) +
                            ", " + std::to_string(want.feature_dim()) + ", " + std::to_string(want.hidden_layers) +
                            " of " + std::to_string(want.hidden_width));
    if (appearance_views_in_checkpoint(c).size() != trainer.data().train.size())
      throw CheckpointError(c.source.string() + ": the checkpoint's appearance model has embeddings for " +
                            std::to_string(appearance_views_in_checkpoint(c).size()) +
                            " training views, this run has " + std::to_string(trainer.data().train.size()));
    look.settings = want;  // rates and test-time settings are the run's
    trainer.mutable_appearance() = std::move(look);
  }
  // The background model likewise.
  const bool ckpt_sky = c.metadata.contains("background"), run_sky = trainer.config().background.enabled;
  if (ckpt_sky != run_sky)
    throw CheckpointError(c.source.string() + ": the checkpoint was trained " + (ckpt_sky ? "with" : "without") +
                          " the background model but this run has it " + (run_sky ? "on" : "off") +
                          " (--effects must match the run being resumed)");
  if (run_sky) {
    BackgroundModel sky = background_from_checkpoint(c);
    const BackgroundSettings& want = trainer.config().background;
    const BackgroundSettings& got = sky.settings;
    if (got.image_dim != want.image_dim || got.hidden_width != want.hidden_width ||
        got.hidden_layers != want.hidden_layers || got.sh_degree != want.sh_degree)
      throw CheckpointError(c.source.string() + ": the checkpoint's background model has image embeddings of " +
                            std::to_string(got.image_dim) + ", " + std::to_string(got.hidden_layers) +
                            " hidden layers of " + std::to_string(got.hidden_width) + " and SH degree " +
                            std::to_string(got.sh_degree) + "; this run asks for " + std::to_string(want.image_dim) +
                            ", " + std::to_string(want.hidden_layers) + " of " + std::to_string(want.hidden_width) +
                            " and " + std::to_string(want.sh_degree));
    if (got.share_appearance_embedding != trainer.shared_embedding())
      throw CheckpointError(c.source.string() + ": the checkpoint's background model reads " +
                            (got.share_appearance_embedding ? "the appearance embeddings" : "its own embeddings") +
                            "; this run's would read " +
                            (trainer.shared_embedding() ? "the appearance embeddings" : "its own") +
                            " (background.share_appearance_embedding must match the run being resumed)");
    if (sky.views() != trainer.data().train.size())
      throw CheckpointError(c.source.string() + ": the checkpoint's background model has embeddings for " +
                            std::to_string(sky.views()) + " training views, this run has " +
                            std::to_string(trainer.data().train.size()));
    sky.settings = want;  // rates and L_bg's settings are the run's
    trainer.mutable_background() = std::move(sky);
  }
  const int64_t step = integer_field(c, c.metadata, "step", "step", 0,
                                     std::max<int64_t>(kMaxCheckpointStep, trainer.config().iterations));
  get_trainable(c, "static", g);
  g.adam_step = integer_field(c, c.metadata, "adam_step", "adam_step", 0, step);
  g.statistics_empty = bool_field(c, c.metadata, "statistics_empty", "statistics_empty");
  if (!views.empty()) {
    const nlohmann::json& d = c.metadata.at("distractors");
    for (const char* list : {"adam_step", "statistics_empty"})
      if (!d.contains(list) || !d.at(list).is_array() || d.at(list).size() != views.size())
        refuse(c, std::string("metadata field 'distractors.") + list + "' is not a list of " +
                      std::to_string(views.size()) + " entries, one per distractor buffer");
  }
  for (size_t v = 0; v < views.size(); ++v) {
    get_trainable(c, distractor_prefix(v), distractors[v]);
    const nlohmann::json& d = c.metadata.at("distractors");
    std::string at(1, '[');
    at += std::to_string(v);
    at += ']';
    distractors[v].adam_step = integer_value(c, d.at("adam_step").at(v), "distractors.adam_step" + at, 0, step);
    distractors[v].statistics_empty =
        bool_value(c, d.at("statistics_empty").at(v), "distractors.statistics_empty" + at);
  }
  // Checkpoints from before the growth rules (docs/METHOD.md §7, growth control) lack the per-view residual:
  // it is then re-measured at each view's next step.
  if (!views.empty() && c.contains("trainer/view_seed_due")) {
    const uint64_t nv = views.size();
    trainer.view_static_unexplained = finite_array(c, "trainer/view_static_unexplained", {nv}, true);
    trainer.view_composite_unexplained = finite_array(c, "trainer/view_composite_unexplained", {nv}, true);
    trainer.view_seed_due = c.get<int32_t>("trainer/view_seed_due", {nv});
    for (size_t v = 0; v < nv; ++v)
      if (trainer.view_seed_due[v] != 0 && trainer.view_seed_due[v] != 1)
        refuse(c, "array 'trainer/view_seed_due' holds " + std::to_string(trainer.view_seed_due[v]) + " at element " +
                      std::to_string(v) + " (a flag: 0 or 1)");
  }
  // The view order is a permutation of this run's training views (or empty: drawn at the next
  // step), and its position lies within it.
  const std::vector<int32_t>& order = c.get<int32_t>("trainer/view_order");
  const size_t train_views = trainer.data().train.size();
  if (!order.empty() && order.size() != train_views)
    refuse(c, "array 'trainer/view_order' lists " + std::to_string(order.size()) + " views but this run has " +
                  std::to_string(train_views) + " training views");
  std::vector<bool> seen(train_views, false);
  for (size_t i = 0; i < order.size(); ++i) {
    if (order[i] < 0 || size_t(order[i]) >= train_views || seen[size_t(order[i])])
      refuse(c, "array 'trainer/view_order' holds " + std::to_string(order[i]) + " at element " + std::to_string(i) +
                    ", not a permutation of the training views 0.." + std::to_string(train_views - 1));
    seen[size_t(order[i])] = true;
  }
  trainer.view_order = order;
  trainer.view_order_pos =
      integer_field(c, c.metadata, "view_order_pos", "view_order_pos", 0, int64_t(trainer.view_order.size()));
  if (!c.metadata.contains("rng") || !c.metadata.at("rng").is_string())
    refuse(c, "metadata field 'rng' is missing or not text");
  try {
    restore_rng_state(trainer.rng(), c.metadata.at("rng").get<std::string>());
  } catch (const CheckpointError& e) {
    refuse(c, e.what());
  }
  trainer.set_step(step);
}

}  // namespace desplat
