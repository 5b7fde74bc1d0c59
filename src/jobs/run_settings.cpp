// A training run's settings, resolved in one place (run_settings.hpp gives the order).
#include "desplat/jobs/run_settings.hpp"

#include <cstdio>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include "desplat/core/stopwatch.hpp"
#include "desplat/io/json_text.hpp"
#include "desplat/train/effects.hpp"
#include "desplat/train/presets.hpp"
#include "desplat/train/train_config_json.hpp"
#include "desplat/train/trainer.hpp"
#include "desplat/train/transient_probe.hpp"
#include "jobs/text_format.hpp"

namespace desplat {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const char* json_kind(const json& j) { return j.type_name(); }

// The first `shown` items joined by `separator`, then "and N more": a long list of settings
// would bury the first ones, which name the problem.
std::string first_items(const std::vector<std::string>& items, size_t shown, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < std::min(items.size(), shown); ++i) out += (i ? separator : "") + items[i];
  if (items.size() > shown) out += separator + "and " + std::to_string(items.size() - shown) + " more";
  return out;
}

// --effects auto's evidence, for config.json and metrics.json.
json effects_evidence_json(const EffectsEvidence& ev, const std::vector<std::string>& reasons) {
  json views = json::array();
  for (const ViewEvidence& v : ev.views)
    views.push_back(
        {{"name", v.name}, {"samples", v.samples}, {"log2_gain", v.log2_gain}, {"open_top_share", v.open_top_share}});
  return {{"reasons", reasons},
          {"judged_views", ev.judged_views},
          {"exposure_spread_stops", ev.exposure_spread_stops},
          {"white_balance_spread", ev.white_balance_spread},
          {"open_top_share", ev.open_top_share},
          {"views", views}};
}

// The transient probe's evidence: per training view, the share of its frame in view-specific areas.
json transient_evidence_json(const TransientEvidence& te, const TrainingData& data) {
  json views = json::array();
  for (size_t v = 0; v < te.view_share.size() && v < data.train.size(); ++v)
    views.push_back({{"name", data.train[v].name}, {"view_specific_share", te.view_share[v]}});
  return {{"reason", te.reason},
          {"judged_views", te.judged_views},
          {"views_with_transients", te.views_with_transients},
          {"transients", te.transients},
          {"views", views}};
}

// Whether the command names any setting beyond the run's length and threads.
bool names_settings(const TrainingRunOptions& opt) {
  return opt.preset || !opt.config.empty() || (opt.effects && *opt.effects != "auto") || opt.seed || opt.batch ||
         opt.static_only || opt.distractors_per_view || opt.no_distractor_density || opt.no_regularization;
}

// --resume continues the model with the settings it was trained with (`trained_with`, from
// config.json): a forgotten --preset or --config must not silently train the rest of the run
// differently. The length of the run, the threads and the kernels' instruction set may change
// (the last two move results by float rounding at most); they come from the command line or
// config file when named there. Any other setting named there (`asked` is what it gives) must
// agree with the record, or the resume is refused naming every setting that differs.
TrainConfig settings_to_resume(const TrainConfig& trained_with, const TrainConfig& asked, const TrainingData& data,
                               const TrainingRunOptions& opt, const json& config_overrides, const json& resumed_run,
                               const std::string& record) {
  if (names_settings(opt)) {
    const std::vector<std::string> differ = config_differences(effective_config(asked, data), trained_with, record,
                                                               {"iterations", "threads", "kernel_isa"});
    if (!differ.empty()) {
      const std::string list = first_items(differ, 6, "; ");
      throw std::invalid_argument(
          "--resume continues the model with the settings it was trained with, and this "
          "command changes " +
          std::to_string(differ.size()) + " of them: " + list +
          ". Resume without settings options (the run was started with --preset " +
          resumed_run.value("preset", std::string("default")) + " and effects " +
          resumed_run.value("effects", std::string("unrecorded")) +
          "), or start again with --overwrite to train with new ones");
    }
  }
  TrainConfig out = trained_with;
  if (opt.iterations || config_overrides.contains("iterations")) out.iterations = asked.iterations;
  if (opt.threads || config_overrides.contains("threads")) out.threads = asked.threads;
  if (config_overrides.contains("kernel_isa")) out.kernel_isa = asked.kernel_isa;
  return out;
}

// --effects auto on a fresh run: appearance and background from the evidence, distractors (as
// configured, on by default) kept only where a short static-only probe finds transients.
// nullopt: interrupted during the probe.
std::optional<json> choose_effects_automatically(TrainConfig& config, const TrainingData& data,
                                                 const std::atomic<bool>& stop_requested, Communicator* comm) {
  const EffectsEvidence ev = examine_effects(data, {}, comm);
  std::vector<std::string> why;
  Effects chosen = choose_effects(Effects::of(config), ev, why);
  // The per-image models train in one process only (Trainer; docs/METHOD.md §6, ranks): a
  // job of several ranks leaves them out and says so.
  if (comm && comm->size() > 1 && (chosen.appearance || chosen.background)) {
    for (const char* model : {"appearance", "background"})
      if (std::string(model) == "appearance" ? chosen.appearance : chosen.background)
        why.push_back(std::string(model) + " left off after all: this job has " + std::to_string(comm->size()) +
                      " ranks, and the " + model +
                      " model trains in one process only (run without mpirun/srun "
                      "to model it)");
    chosen.appearance = chosen.background = false;
  }
  json transients = nullptr;
  if (chosen.distractors) {
    // The probe runs with the appearance and background just chosen.
    Effects probe_set = chosen;
    probe_set.distractors = false;
    TrainConfig probe_config = config;
    probe_set.apply(probe_config);
    const TransientRules rules;
    std::printf("--effects auto: probing for transients (%d static-only steps at 1/%d resolution)\n", rules.probe_steps,
                data.train.empty() ? 1 : probe_factor(data.train[0].camera.width, data.train[0].camera.height, rules));
    const Stopwatch probe_clock;
    const std::optional<TransientEvidence> probed = probe_transients(data, probe_config, rules, &stop_requested, comm);
    if (!probed) return std::nullopt;
    const TransientEvidence& te = *probed;
    const double probe_seconds = probe_clock.seconds();
    chosen.distractors = te.transients;
    why.insert(why.begin(), std::string("distractors ") + (te.transients ? "on" : "off") + ": " + te.reason);
    transients = transient_evidence_json(te, data);
    transients["probe_seconds"] = probe_seconds;
    std::printf("--effects auto: the probe took %.1f s\n", probe_seconds);
  } else {
    why.insert(why.begin(), "distractors off: the preset and --config turn them off");
  }
  chosen.apply(config);
  std::printf("--effects auto: %s\n", chosen.to_string().c_str());
  for (const std::string& line : why) std::printf("  %s\n", line.c_str());
  json evidence = effects_evidence_json(ev, why);
  evidence["transients"] = transients;
  return evidence;
}

}  // namespace

json read_config_option(const std::string& config) {
  const size_t first = config.find_first_not_of(" \t\r\n");
  const bool inline_text = first != std::string::npos && (config[first] == '{' || config[first] == '[');
  const std::string source = inline_text ? "--config text" : "--config file " + config;
  std::string text = config;
  if (!inline_text) {
    std::error_code ec;
    if (!fs::is_regular_file(config, ec))
      throw std::invalid_argument("--config '" + config +
                                  "' is neither a JSON object of settings (e.g. --config "
                                  "'{\"num_downscales\": 0}') nor a file that exists: give one of the two");
    std::ifstream f(config);
    if (!f) throw std::invalid_argument("cannot read " + source + ": check its permissions");
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  json j;
  try {
    j = parse_json_bounded(text, source);
  } catch (const JsonTextError& e) {
    throw std::invalid_argument(std::string(e.what()) + "; fix it or give the settings inline");
  }
  if (!j.is_object())
    throw std::invalid_argument(source + " must be a JSON object of settings such as {\"num_downscales\": 0} (got " +
                                std::string(json_kind(j)) + "): docs/CONFIG.md lists every setting");
  // A run's own config.json: {"train": settings, "scene": recipe, "run": record}.
  const bool run_record = j.contains("train") && j.at("train").is_object() &&
                          std::all_of(j.items().begin(), j.items().end(), [](const auto& item) {
                            return item.key() == "train" || item.key() == "scene" || item.key() == "run";
                          });
  if (run_record) {
    if (j.size() > 1)
      std::printf(
          "%s is a run's config.json: its \"train\" settings apply; its \"scene\" and \"run\" records are "
          "ignored (this run's data, split and effects come from --data, the split options and --effects)\n",
          source.c_str());
    j = j.at("train");
  }
  try {
    config_from_json(j, TrainConfig{});  // names the source with the first bad setting
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(source + ": " + e.what());
  }
  return j;
}

RequestedSettings request_settings(const TrainingRunOptions& opt) {
  RequestedSettings r;
  r.preset = opt.preset.value_or("default");
  TrainConfig config = preset_config(r.preset);
  if (!opt.config.empty()) {
    r.overrides = read_config_option(opt.config);  // checked there, naming its source
    config = config_from_json(r.overrides, config);
  }
  if (opt.iterations) config.iterations = *opt.iterations;
  if (opt.seed) config.seed = *opt.seed;
  if (opt.batch) config.batch = *opt.batch;
  if (opt.threads) config.threads = *opt.threads;
  if (config.iterations < 1) throw std::invalid_argument("--iterations must be at least 1");
  if (opt.static_only && opt.effects && *opt.effects != "none")
    throw std::invalid_argument("--static-only and --effects " + *opt.effects + " contradict each other");
  if (opt.static_only) config.distractors.enabled = false;
  // --effects defaults to auto; --static-only means none, and --preset paper keeps the
  // authors' set (distractors only) unless --effects says otherwise. An empty list is an error.
  if (opt.effects) {
    r.auto_effects = *opt.effects == "auto";
    if (!r.auto_effects) Effects::parse(*opt.effects).apply(config);
  } else if (opt.static_only) {
    Effects::parse("none").apply(config);
  } else {
    r.auto_effects = r.preset != "paper";
  }
  if (opt.distractors_per_view) {
    config.distractors.initial_count = *opt.distractors_per_view;
    config.distractors.reference_pixels = 0;  // exactly that many, whatever the image size
  }
  if (opt.no_distractor_density) config.distractors.density_control = false;
  if (opt.no_regularization) config.distractors.regularize = false;
  validate_config(config);
  r.config = config;
  return r;
}

std::optional<ResolvedSettings> resolve_settings(const RequestedSettings& requested, const TrainingRunOptions& opt,
                                                 const TrainingData& data, const ModelFolder::Config* resumed,
                                                 const std::string& record_name,
                                                 const std::atomic<bool>& stop_requested, Communicator* comm) {
  ResolvedSettings out;
  out.config = requested.config;
  const json resumed_run = resumed ? resumed->run : json::object();
  out.effects_chosen_by = requested.auto_effects ? "auto" : "the command line and preset";
  out.effects_evidence = nullptr;
  if (requested.auto_effects && resumed_run.contains("effects")) {
    // A resumed run continues the model it resumes, with the effects it was trained with
    // (auto's probe is not repeated: it would take up to a minute to give the same answer).
    Effects::parse(resumed_run.at("effects").get<std::string>()).apply(out.config);
    out.effects_evidence = resumed_run.value("effects_evidence", json(nullptr));
    std::printf("--effects auto: %s, as this model was trained\n", Effects::of(out.config).to_string().c_str());
  } else if (requested.auto_effects) {
    const std::optional<json> evidence = choose_effects_automatically(out.config, data, stop_requested, comm);
    if (!evidence) return std::nullopt;
    out.effects_evidence = *evidence;
  }
  if (resumed && !resumed->unrecorded_settings.empty()) {
    // Said before anything trains: the rest of the run uses today's defaults for them.
    const std::vector<std::string>& missing = resumed->unrecorded_settings;
    std::printf(
        "warning: %s records no value for %zu setting%s (%s): it was written by an older desplat, and the "
        "resumed run uses today's defaults for them\n",
        record_name.c_str(), missing.size(), missing.size() == 1 ? "" : "s", first_items(missing, 6, ", ").c_str());
  }
  if (resumed)
    out.config =
        settings_to_resume(resumed->train, out.config, data, opt, requested.overrides, resumed_run, record_name);
  out.run = {{"static_only", opt.static_only},
             {"preset", resumed_run.value("preset", requested.preset)},
             {"effects", Effects::of(out.config).to_string()},
             {"effects_chosen_by", out.effects_chosen_by},
             {"effects_evidence", out.effects_evidence}};
  return out;
}

}  // namespace desplat
