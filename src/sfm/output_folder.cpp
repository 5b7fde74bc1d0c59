// The output folder of a structure-from-motion run (see src/sfm/pipeline.hpp): created,
// cleared of an earlier run's results only on request, with the photos provided in images/.
#include <algorithm>
#include <fstream>
#include <system_error>

#include "desplat/io/output_folder.hpp"
#include "sfm/pipeline.hpp"
#include "sfm/quoting.hpp"

namespace desplat::sfm::pipeline {
namespace fs = std::filesystem;
namespace {

bool is_inside(const fs::path& inner, const fs::path& outer) {
  const fs::path a = fs::weakly_canonical(inner), b = fs::weakly_canonical(outer);
  auto [end_b, end_a] = std::mismatch(b.begin(), b.end(), a.begin(), a.end());
  return end_b == b.end();
}

// Earlier results are only replaced on request: a mapper run can take hours.
void clear_earlier_results(const Layout& l, bool overwrite) {
  std::error_code ec;
  const fs::path earlier[] = {l.database, l.sparse_root};
  for (const fs::path& p : earlier) {
    if (!fs::exists(fs::symlink_status(p, ec))) continue;
    if (!overwrite)
      fail(SfmErrorKind::OutputExists,
           in_quotes(l.out) + " holds results of an earlier run (" + p.filename().string() +
               "); pass --overwrite to redo structure from motion there, or choose another --out");
    fs::remove_all(p, ec);
    if (ec) fail(SfmErrorKind::OutputExists, "cannot remove " + in_quotes(p) + ": " + ec.message());
  }
  for (const char* suffix : {"-wal", "-shm", "-journal"}) fs::remove(l.database.string() + suffix, ec);
}

void copy_photos(const fs::path& from, const fs::path& to, const std::vector<fs::path>& photos) {
  std::error_code ec;
  for (const fs::path& rel : photos) {
    fs::create_directories((to / rel).parent_path(), ec);
    if (!ec) fs::copy_file(from / rel, to / rel, fs::copy_options::overwrite_existing, ec);
    if (ec)
      fail(SfmErrorKind::OutputExists,
           "cannot copy " + in_quotes(from / rel) + " to " + in_quotes(to / rel) + ": " + ec.message());
  }
}

// <out>/images: the input itself, a symlink to it, or a copy of its photos.
void provide_images(const SfmOptions& o, const Layout& l, const std::vector<fs::path>& photos) {
  std::error_code ec;
  const auto st = fs::symlink_status(l.images, ec);
  if (fs::exists(st)) {
    if (fs::equivalent(l.images, o.images, ec)) return;  // the input already is <out>/images
    if (!fs::is_symlink(st))
      fail(SfmErrorKind::OutputExists,
           in_quotes(l.images) + " already exists and is not the images folder; remove it or choose another --out");
    fs::remove(l.images, ec);  // a stale link from an earlier run: removing it loses no data
  }
  if (o.copy_images) return copy_photos(o.images, l.images, photos);
  fs::create_directory_symlink(fs::canonical(o.images), l.images, ec);
  if (ec)
    fail(SfmErrorKind::OutputExists, "cannot create the symlink " + in_quotes(l.images) + ": " + ec.message() +
                                         "; pass --copy-images to copy the photos instead");
}

void write_image_list(const fs::path& path, const std::vector<fs::path>& photos) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  for (const fs::path& p : photos) f << p.generic_string() << '\n';
  if (!f.flush()) fail(SfmErrorKind::OutputExists, "cannot write " + in_quotes(path));
}

}  // namespace

void prepare_output(const SfmOptions& o, const Layout& l, const std::vector<fs::path>& photos) {
  std::error_code ec;
  if (is_inside(o.out, o.images))
    fail(SfmErrorKind::OutputExists, "--out " + in_quotes(o.out) + " is inside the images folder " +
                                         in_quotes(o.images) + "; choose an --out outside it");
  // A COLMAP project's own images folder (--images is <out>/images) is used in place; any
  // other overlap of --out with the photos is refused.
  std::error_code same_ec;
  const bool in_place = fs::equivalent(o.images, l.images, same_ec);
  try {
    check_output_folder("--out", o.out, {{"--images", in_place ? fs::path() : o.images}});
  } catch (const std::invalid_argument& e) {
    fail(SfmErrorKind::OutputExists, e.what());
  }
  fs::create_directories(o.out, ec);
  if (ec || !fs::is_directory(o.out))
    fail(SfmErrorKind::OutputExists,
         "cannot create the output folder " + in_quotes(o.out) + (ec ? ": " + ec.message() : ""));
  clear_earlier_results(l, o.overwrite);
  provide_images(o, l, photos);
  write_image_list(l.image_list, photos);
}

}  // namespace desplat::sfm::pipeline
