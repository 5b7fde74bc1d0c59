// Train/test splits of a capture's images (docs/METHOD.md §8).
//
// Every rule sees the registered image names exactly as the COLMAP model stores them
// (paths relative to images/, e.g. "0001.jpg" or "cam0/0001.jpg") and gives each one a
// role: Train, Test, or Unused (left out of the scene, e.g. RobustNeRF's clean images when
// training on clutter). Rules that look at names match the file name (the part after the
// last '/').
//
//   EveryNth      sorted by name (byte order), position % every_nth == 0 is Test, the rest
//                 Train. This is the mip-NeRF 360 / 3DGS "llffhold" convention with 8.
//                 nerfstudio's interval split is the same rule on COLMAP image-id order, which
//                 is name order whenever COLMAP numbered the images in name order (its
//                 feature extractor does).
//   AllTrain      everything Train, no test views.
//   NameLists     files with one image name per line (blank lines and lines starting with '#'
//                 are skipped, surrounding whitespace trimmed), or the same lists given as
//                 names (train_names / test_names: how a trained model reopens its exact
//                 views). Both lists: listed names get that role, the rest are Unused. Only a
//                 test list: the rest are Train. Only a train list: the rest are Test.
//   RobustNeRF    the file name contains exactly one of "clutter", "extra", "clean" (RobustNeRF
//                 names its files e.g. "1extra000.JPG", "2clutter008.JPG"). extra → Test
//                 always. Without clutter_ratio: clutter → Train, clean → Unused. With
//                 clutter_ratio r ∈ [0, 1] (the clean/clutter study): clean and clutter names
//                 are each sorted, truncated to the shorter length n, and paired in order
//                 (clean[k], clutter[k]) — the k-th poses of the two captures. m = ⌊n·r⌋ pairs
//                 train on their clutter image, the others on their clean image; the
//                 other image of each pair is Unused. The m cluttered pairs are spread evenly:
//                 pair k is cluttered when ⌊(k+1)·m/n⌋ > ⌊k·m/n⌋. (The authors pick them with
//                 a seeded torch permutation instead, so the exact set differs; the counts
//                 are the same.)
//   OnTheGo       "extra" in the file name → Test, everything else Train (NeRF On-the-go).
//   PhotoTourism  a NeRF-W style .tsv: a header line naming tab-separated columns including
//                 "filename", "id" and "split"; rows with an empty or "nan" id are skipped (as
//                 NeRF-W does); split "train" → Train, "test" → Test; registered images the
//                 file does not mention are Unused.
//
// Errors (SplitError, naming the file and line where there is one): an option that the
// chosen rule does not use (conflicting options), every_nth < 2, clutter_ratio outside
// [0, 1], a list naming an image the model does not have, a name in both lists or listed
// twice with different splits, a RobustNeRF name matching none or several of the keywords,
// an unknown split value, a malformed .tsv, and a result with no Train view.
#pragma once

#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace desplat {

struct SplitError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

enum class SplitRule { EveryNth, AllTrain, NameLists, RobustNeRF, OnTheGo, PhotoTourism };
enum class ViewRole { Train, Test, Unused };

struct SplitOptions {
  SplitRule rule = SplitRule::EveryNth;
  int every_nth = 8;                 // EveryNth only (other rules need the default)
  std::filesystem::path train_list;  // NameLists only
  std::filesystem::path test_list;   // NameLists only
  // NameLists only: a list given as its names instead of a file (present, even if empty, = given).
  std::optional<std::vector<std::string>> train_names, test_names;
  std::optional<double> clutter_ratio;  // RobustNeRF only
  std::filesystem::path tsv;            // PhotoTourism only
};

// Parses a rule name as used on command lines: "every-nth", "all-train", "lists",
// "robustnerf", "onthego", "phototourism". Throws SplitError listing the names.
SplitRule split_rule_from_name(const std::string& name);
// The command-line name of a rule (the inverse of split_rule_from_name).
const char* split_rule_name(SplitRule rule);

// The role of each name, in the order given. Names must be unique (COLMAP's are).
std::vector<ViewRole> assign_split(const std::vector<std::string>& names, const SplitOptions& options);

}  // namespace desplat
