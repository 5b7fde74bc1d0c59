#include "desplat/io/output_folder.hpp"

#include <system_error>

namespace desplat {

namespace fs = std::filesystem;

namespace {

// The absolute path with symlinks of its existing part resolved and "." / ".." removed.
fs::path resolved(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p), ec);
  if (ec) r = fs::absolute(p).lexically_normal();
  // A trailing separator gives an empty last element; drop it so "a/" equals "a".
  if (!r.empty() && r.filename().empty() && r != r.root_path()) r = r.parent_path();
  return r;
}

// `inner` equals `outer` or lies below it (component-wise, both resolved).
bool within(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

void check_output_folder(const std::string& out_option, const fs::path& out, const std::vector<ReadLocation>& inputs) {
  if (out.empty()) throw std::invalid_argument(out_option + " is empty: give the folder to write the outputs into");
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_directory(out, ec))
    throw std::invalid_argument(out_option + " " + out.string() +
                                " is a file, not a folder: choose a folder (it is created if missing)");
  const fs::path o = resolved(out);
  if (o == o.root_path())
    throw std::invalid_argument(out_option + " " + out.string() +
                                " is the filesystem root: choose a folder of its own for the outputs");
  for (const ReadLocation& in : inputs) {
    if (in.path.empty()) continue;
    const fs::path i = resolved(in.path);
    const std::string both = out_option + " " + out.string() + " and " + in.option + " " + in.path.string();
    if (o == i)
      throw std::invalid_argument(both + " are the same folder: the input is never written; choose another " +
                                  out_option);
    if (within(o, i) && !in.output_may_lie_inside)
      throw std::invalid_argument(out_option + " " + out.string() + " lies inside " + in.option + " " +
                                  in.path.string() + ": the input is never written; choose a folder outside it");
    if (within(i, o))
      throw std::invalid_argument(out_option + " " + out.string() + " contains " + in.option + " " + in.path.string() +
                                  ": the outputs would be written among the inputs; choose a folder that does not "
                                  "hold them");
  }
}

}  // namespace desplat
