// The train/test split options every app that loads a scene offers (docs/METHOD.md §8).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "desplat/io/splits.hpp"

namespace desplat::apps {

// Adds --split, --test-every, --train-list, --test-list, --clutter-ratio and --tsv; `rule` gets
// the --split name, to be turned into split.rule with split_rule_from_name after parsing.
inline void add_split_options(CLI::App& app, SplitOptions& split, std::string& rule) {
  app.add_option("--split", rule, "train/test split: every-nth, all-train, lists, robustnerf, onthego, phototourism")
      ->capture_default_str();
  app.add_option("--test-every", split.every_nth, "every-nth split: hold out every Nth image")->capture_default_str();
  app.add_option("--train-list", split.train_list, "lists split: file with one training image name per line");
  app.add_option("--test-list", split.test_list, "lists split: file with one test image name per line");
  app.add_option("--clutter-ratio", split.clutter_ratio, "robustnerf split: share of cluttered training views (0..1)");
  app.add_option("--tsv", split.tsv, "phototourism split: the .tsv split file");
}

}  // namespace desplat::apps
