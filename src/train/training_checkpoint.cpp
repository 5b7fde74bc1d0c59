// Names of the checkpoint arrays, for a prefix P = "static" or "distractor/<train view index>":
// "P/<group>", "P/adam_m/<group>", "P/adam_v/<group>", "P/stats/<name>"; and
// "trainer/view_order", and per training view (distractors on) "trainer/view_static_unexplained",
// "trainer/view_composite_unexplained", "trainer/view_seed_due". Per-set scalars (Adam step, statistics flag) are in the metadata:
// "adam_step"/"statistics_empty"/"feature_dim" for the static set, and with the appearance model
// "appearance/mlp", "appearance/image_embeddings" and their "appearance/adam_m/…", "…/adam_v/…"
// with metadata "appearance": {"views", "image_dim", "fourier_frequencies", "hidden_width",
// "hidden_layers", "adam_step"}; with the background model the same under "background/…" and
// metadata "background": {"views", "image_dim", "hidden_width", "hidden_layers", "sh_degree",
// "adam_step"}; "distractors": {"views": [names],
// "adam_step": [...], "statistics_empty": [...]} for the per-view sets.
#include "desplat/train/training_checkpoint.hpp"

namespace desplat {
namespace {

std::string distractor_prefix(size_t view) { return "distractor/" + std::to_string(view); }

// The arrays of a per-image model (AppearanceModel, BackgroundModel): "P/mlp",
// "P/image_embeddings" and their "P/adam_m/…", "P/adam_v/…".
template <class Model> void put_per_image_model(Checkpoint& c, const std::string& prefix, const Model& m) {
  const uint64_t views = m.views(), dim = uint64_t(m.settings.image_dim), weights = m.mlp.size();
  c.put(prefix + "/mlp", {weights}, m.mlp);
  c.put(prefix + "/adam_m/mlp", {weights}, m.mlp_m);
  c.put(prefix + "/adam_v/mlp", {weights}, m.mlp_v);
  c.put(prefix + "/image_embeddings", {views, dim}, m.image_embeddings);
  c.put(prefix + "/adam_m/image_embeddings", {views, dim}, m.embed_m);
  c.put(prefix + "/adam_v/image_embeddings", {views, dim}, m.embed_v);
}

// `m.settings` must be set (it gives the shapes).
template <class Model> void get_per_image_model(const Checkpoint& c, const std::string& prefix, size_t views, Model& m) {
  const uint64_t weights = m.mlp_floats(), dim = uint64_t(m.settings.image_dim);
  m.mlp = c.get<float>(prefix + "/mlp", {weights});
  m.mlp_m = c.get<float>(prefix + "/adam_m/mlp", {weights});
  m.mlp_v = c.get<float>(prefix + "/adam_v/mlp", {weights});
  m.image_embeddings = c.get<float>(prefix + "/image_embeddings", {views, dim});
  m.embed_m = c.get<float>(prefix + "/adam_m/image_embeddings", {views, dim});
  m.embed_v = c.get<float>(prefix + "/adam_v/image_embeddings", {views, dim});
  m.adam_step = c.metadata.at(prefix).at("adam_step").get<int64_t>();
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
bool absent_featureless(const Checkpoint& c, const std::string& name, const ParamGroupInfo& info, const GaussianSet& g) {
  return info.id == ParamGroup::Features && g.feature_dim == 0 && !c.contains(name);
}

GaussianSet get_params(const Checkpoint& c, const std::string& prefix, ColorMode mode, int sh_degree, int feature_dim) {
  GaussianSet g;
  g.sh_degree = sh_degree;
  g.color_mode = mode;
  g.feature_dim = feature_dim;
  const uint64_t n = c.array(prefix + "/opacity_logits").shape().at(0);
  for (const ParamGroupInfo& info : kParamGroupTable) {
    const std::string name = prefix + "/" + info.name;
    if (absent_featureless(c, name, info, g)) continue;
    g.*info.values = c.get<float>(name, {n, uint64_t(group_width(info, g))});
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
    g.adam_m[k] = c.get<float>(prefix + "/adam_m/" + kParamGroupTable[k].name, {n, stride});
    g.adam_v[k] = c.get<float>(prefix + "/adam_v/" + kParamGroupTable[k].name, {n, stride});
  }
  g.absgrad_sum = c.get<float>(prefix + "/stats/absgrad_sum", {n});
  g.visible_count = c.get<int32_t>(prefix + "/stats/visible_count", {n});
  g.max_screen_radius = c.get<float>(prefix + "/stats/max_screen_radius", {n});
  g.check_consistent();
}

}  // namespace

Checkpoint make_training_checkpoint(const Trainer& t, const nlohmann::json& extra_metadata) {
  const TrainableGaussians& g = t.gaussians();
  Checkpoint c;
  c.metadata = extra_metadata.is_object() ? extra_metadata : nlohmann::json::object();
  c.metadata["step"] = t.current_step();
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
  const int sh_degree = c.metadata.value("sh_degree", 0);
  const ColorMode mode =
      c.metadata.value("color_mode", std::string("sh")) == "rgb" ? ColorMode::RGB : ColorMode::SphericalHarmonics;
  return get_params(c, "static", mode, sh_degree, c.metadata.value("feature_dim", 0));
}

std::vector<std::string> appearance_views_in_checkpoint(const Checkpoint& c) {
  if (!c.metadata.contains("appearance")) return {};
  return c.metadata.at("appearance").at("views").get<std::vector<std::string>>();
}

AppearanceModel appearance_from_checkpoint(const Checkpoint& c) {
  const std::vector<std::string> views = appearance_views_in_checkpoint(c);
  if (views.empty()) throw CheckpointError(c.source.string() + ": the model was trained without appearance");
  const nlohmann::json& m = c.metadata.at("appearance");
  AppearanceSettings s;
  s.enabled = true;
  s.image_dim = m.at("image_dim").get<int>();
  s.fourier_frequencies = m.at("fourier_frequencies").get<int>();
  s.hidden_width = m.at("hidden_width").get<int>();
  s.hidden_layers = m.at("hidden_layers").get<int>();
  AppearanceModel model;
  model.settings = s;
  get_per_image_model(c, "appearance", views.size(), model);
  return model;
}

std::vector<std::string> background_views_in_checkpoint(const Checkpoint& c) {
  if (!c.metadata.contains("background")) return {};
  return c.metadata.at("background").at("views").get<std::vector<std::string>>();
}

BackgroundModel background_from_checkpoint(const Checkpoint& c) {
  const std::vector<std::string> views = background_views_in_checkpoint(c);
  if (views.empty()) throw CheckpointError(c.source.string() + ": the model was trained without a background model");
  const nlohmann::json& m = c.metadata.at("background");
  BackgroundSettings s;
  s.enabled = true;
  s.image_dim = m.at("image_dim").get<int>();
  s.hidden_width = m.at("hidden_width").get<int>();
  s.hidden_layers = m.at("hidden_layers").get<int>();
  s.sh_degree = m.at("sh_degree").get<int>();
  // Absent in models from before the option: those read their own embeddings.
  s.share_appearance_embedding = m.value("shares_appearance_embedding", false);
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

std::vector<std::string> distractor_views_in_checkpoint(const Checkpoint& c) {
  if (!c.metadata.contains("distractors")) return {};
  return c.metadata.at("distractors").at("views").get<std::vector<std::string>>();
}

GaussianSet distractors_from_checkpoint(const Checkpoint& c, size_t index) {
  return get_params(c, distractor_prefix(index), ColorMode::RGB, 0, 0);
}

void restore_training_checkpoint(Trainer& trainer, const Checkpoint& c) {
  TrainableGaussians& g = trainer.mutable_gaussians();
  const int sh_degree = c.metadata.value("sh_degree", -1);
  if (sh_degree != g.params.sh_degree)
    throw CheckpointError(c.source.string() + ": checkpoint has SH degree " + std::to_string(sh_degree) +
                          " but the configuration asks for " + std::to_string(g.params.sh_degree));
  const std::vector<std::string> views = distractor_views_in_checkpoint(c);
  std::vector<TrainableGaussians>& distractors = trainer.mutable_distractors();
  if (views.size() != distractors.size())
    throw CheckpointError(c.source.string() + ": checkpoint has distractors for " + std::to_string(views.size()) +
                          " views but this run has " + std::to_string(distractors.size()) +
                          (distractors.empty() ? " (distractors are off: --static-only?)" : ""));
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
                            std::to_string(appearance_views_in_checkpoint(c).size()) + " training views, this run has " +
                            std::to_string(trainer.data().train.size()));
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
  get_trainable(c, "static", g);
  g.adam_step = c.metadata.at("adam_step").get<int64_t>();
  g.statistics_empty = c.metadata.at("statistics_empty").get<bool>();
  for (size_t v = 0; v < views.size(); ++v) {
    get_trainable(c, distractor_prefix(v), distractors[v]);
    distractors[v].adam_step = c.metadata.at("distractors").at("adam_step").at(v).get<int64_t>();
    distractors[v].statistics_empty = c.metadata.at("distractors").at("statistics_empty").at(v).get<bool>();
  }
  // Checkpoints from before the growth rules (docs/METHOD.md §7, growth control) lack the per-view residual:
  // it is then re-measured at each view's next step.
  if (!views.empty() && c.contains("trainer/view_seed_due")) {
    const uint64_t nv = views.size();
    trainer.view_static_unexplained = c.get<float>("trainer/view_static_unexplained", {nv});
    trainer.view_composite_unexplained = c.get<float>("trainer/view_composite_unexplained", {nv});
    trainer.view_seed_due = c.get<int32_t>("trainer/view_seed_due", {nv});
  }
  trainer.view_order = c.get<int32_t>("trainer/view_order");
  trainer.view_order_pos = c.metadata.at("view_order_pos").get<int64_t>();
  restore_rng_state(trainer.rng(), c.metadata.at("rng").get<std::string>());
  trainer.set_step(c.metadata.at("step").get<int64_t>());
}

}  // namespace desplat
