// How the SfM layer names a path in a message: in single quotes, so a name with spaces or an
// empty one reads unambiguously.
#pragma once

#include <filesystem>
#include <string>

namespace desplat::sfm {

inline std::string in_quotes(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

}  // namespace desplat::sfm
