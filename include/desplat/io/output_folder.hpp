// The one check every tool makes before it creates or writes its output folder: the folder
// is named, is (or can become) a folder, is not the filesystem root, and does not overlap
// what the tool reads. The inputs are never written (README: "the input is never written"),
// so an output folder that is an input, lies inside one, or holds one is refused before
// anything is created.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace desplat {

// A folder (or file) the tool reads, e.g. {"--data", "/scenes/fox"}.
struct ReadLocation {
  std::string option;  // how the user named it, for the message ("--data", "the model's data folder")
  std::filesystem::path path;
  // The output may be a subfolder of it (desplat_render --out MODEL/renders): only the
  // location itself and anything holding it are refused.
  bool output_may_lie_inside = false;
};

// Throws std::invalid_argument naming `out_option` and the problem:
//   * `out` is empty;
//   * `out` exists and is not a folder (a file, or a symlink to one);
//   * `out` resolves to the filesystem root;
//   * `out` is one of `inputs` (symlinks and "." / ".." resolved), lies inside one (unless it
//     allows that), or contains one.
// Empty input paths are skipped. Creates nothing.
void check_output_folder(const std::string& out_option, const std::filesystem::path& out,
                         const std::vector<ReadLocation>& inputs);

}  // namespace desplat
