// desplat_occlude: makes a capture with known distractors by pasting occluders (shapes and
// patches of other photos) into some of its training views, with ground-truth masks.
// Options only; the job is desplat::occlude_scene (occluders.hpp).
#include <CLI/CLI.hpp>

#include <cstdio>

#include "desplat/io/splits.hpp"
#include "desplat/synth/occluders.hpp"
#include "split_options.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Paste occluders into training views of a COLMAP capture and write the result as a scene.\n"
      "--out gets sparse/0/ (copied), images/ (same names and formats), distractor_masks/ (255 = pasted,\n"
      "one per training view) and occluders.json (what was pasted where). Test views stay untouched."};
  desplat::OccludeOptions o;
  app.add_option("--data", o.data_dir, "scene folder with images/ and sparse/0/ (read only)")->required();
  app.add_option("--out", o.out_dir, "output scene folder (not inside --data)")->required();
  app.add_option("--fraction", o.fraction, "share of the training views that get occluders (0..1)")
      ->capture_default_str();
  app.add_option("--seed", o.seed, "random seed: same seed, same files")->capture_default_str();
  app.add_option("--coverage-min", o.coverage_min, "least share of an occluded view's pixels covered")
      ->capture_default_str();
  app.add_option("--coverage-max", o.coverage_max, "largest share of an occluded view's pixels covered (<= 0.6)")
      ->capture_default_str();
  app.add_option("--track", o.track_length,
                 "runs of N consecutive training views share one set of occluders (something that stays in frame)")
      ->capture_default_str();
  app.add_flag("--overwrite", o.overwrite, "replace a scene already written to --out");
  std::string split_rule = "every-nth";
  desplat::apps::add_split_options(app, o.split, split_rule);
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "desplat_occlude: error: %s (see --help)\n", e.what());
    return 2;
  }
  try {
    o.split.rule = desplat::split_rule_from_name(split_rule);
    const desplat::OccludeReport report = desplat::occlude_scene(o);
    int train = 0, occluded = 0;
    for (const auto& v : report.views) {
      train += v.role == desplat::ViewRole::Train;
      occluded += v.occluded;
    }
    std::printf("desplat_occlude: %d of %d training views occluded; wrote %s\n", occluded, train,
                o.out_dir.string().c_str());
    return 0;
  } catch (const std::exception& e) {  // bad input: OccludeError / SplitError name the problem
    std::fprintf(stderr, "desplat_occlude: error: %s\n", e.what());
    return 2;
  }
}
