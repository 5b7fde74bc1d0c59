// Names of the checkpoint arrays: "static/<group>", "static/adam_m/<group>",
// "static/adam_v/<group>", "static/stats/<name>", "trainer/view_order".
#include "desplat/training_checkpoint.hpp"


namespace desplat {
namespace {

const char* kGroupNames[kParamGroups] = {"means", "log_scales", "quats", "opacity_logits", "colors"};

}  // namespace

Checkpoint make_training_checkpoint(const Trainer& trainer, const nlohmann::json& extra_metadata) {
  const Trainer& t = trainer;
  const TrainableGaussians& g = t.gaussians();
  Checkpoint c;
  c.metadata = extra_metadata.is_object() ? extra_metadata : nlohmann::json::object();
  c.metadata["step"] = trainer.current_step();
  c.metadata["adam_step"] = g.adam_step;
  c.metadata["statistics_empty"] = g.statistics_empty;
  c.metadata["sh_degree"] = g.params.sh_degree;
  c.metadata["color_mode"] = g.params.color_mode == ColorMode::RGB ? "rgb" : "sh";
  c.metadata["view_order_pos"] = t.view_order_pos;
  c.metadata["rng"] = save_rng_state(t.rng());
  const uint64_t n = g.size();
  for (int k = 0; k < kParamGroups; ++k) {
    const uint64_t stride = g.floats_per_gaussian(ParamGroup(k));
    const std::string name = kGroupNames[k];
    c.put("static/" + name, {n, stride}, g.param(ParamGroup(k)));
    c.put("static/adam_m/" + name, {n, stride}, g.adam_m[k]);
    c.put("static/adam_v/" + name, {n, stride}, g.adam_v[k]);
  }
  c.put("static/stats/absgrad_sum", {n}, g.absgrad_sum);
  c.put("static/stats/visible_count", {n}, g.visible_count);
  c.put("static/stats/max_screen_radius", {n}, g.max_screen_radius);
  c.put("trainer/view_order", {t.view_order.size()}, t.view_order);
  return c;
}

GaussianSet gaussians_from_checkpoint(const Checkpoint& c) {
  GaussianSet g;
  g.sh_degree = c.metadata.value("sh_degree", 0);
  g.color_mode = c.metadata.value("color_mode", std::string("sh")) == "rgb" ? ColorMode::RGB : ColorMode::SphericalHarmonics;
  const uint64_t n = c.array("static/opacity_logits").shape().at(0);
  const uint64_t strides[kParamGroups] = {3, 3, 4, 1, uint64_t(g.view().color_floats_per_gaussian())};
  std::vector<float>* dst[kParamGroups] = {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.colors};
  for (int k = 0; k < kParamGroups; ++k) *dst[k] = c.get<float>(std::string("static/") + kGroupNames[k], {n, strides[k]});
  return g;
}

void restore_training_checkpoint(Trainer& trainer, const Checkpoint& c) {
  TrainableGaussians& g = trainer.mutable_gaussians();
  const int sh_degree = c.metadata.value("sh_degree", -1);
  if (sh_degree != g.params.sh_degree)
    throw CheckpointError(c.source.string() + ": checkpoint has SH degree " + std::to_string(sh_degree) +
                          " but the configuration asks for " + std::to_string(g.params.sh_degree));
  g.params = gaussians_from_checkpoint(c);
  const uint64_t n = g.size();
  for (int k = 0; k < kParamGroups; ++k) {
    const uint64_t stride = g.floats_per_gaussian(ParamGroup(k));
    g.adam_m[k] = c.get<float>(std::string("static/adam_m/") + kGroupNames[k], {n, stride});
    g.adam_v[k] = c.get<float>(std::string("static/adam_v/") + kGroupNames[k], {n, stride});
  }
  g.absgrad_sum = c.get<float>("static/stats/absgrad_sum", {n});
  g.visible_count = c.get<int32_t>("static/stats/visible_count", {n});
  g.max_screen_radius = c.get<float>("static/stats/max_screen_radius", {n});
  g.adam_step = c.metadata.at("adam_step").get<int64_t>();
  g.statistics_empty = c.metadata.at("statistics_empty").get<bool>();
  g.check_consistent();
  trainer.view_order = c.get<int32_t>("trainer/view_order");
  trainer.view_order_pos = c.metadata.at("view_order_pos").get<int64_t>();
  restore_rng_state(trainer.rng(), c.metadata.at("rng").get<std::string>());
  trainer.set_step(c.metadata.at("step").get<int64_t>());
}

}  // namespace desplat
