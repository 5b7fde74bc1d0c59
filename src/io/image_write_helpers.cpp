// Encode in memory, then one checked, atomic write (see image_write_helpers.hpp). OpenImageIO's
// own file output does not report a failed write on every format: PNGs written onto a full
// disk came out as 0-byte files with success reported.
#include "io/image_write_helpers.hpp"

#include <OpenImageIO/filesystem.h>

#include <string>
#include <string_view>
#include <vector>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/image_io.hpp"

namespace desplat {

void write_encoded_image(const std::filesystem::path& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                         const void* pixels, const char* what) {
  const std::string fail = std::string("cannot write the ") + what + " " + path.string() + ": ";
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out) throw ImageError(fail + OIIO::geterror());
  if (!out->supports("ioproxy"))
    throw ImageError(fail + "the " + out->format_name() + " format cannot be written in memory; use .png or .jpg");
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput memory(bytes);
  if (!out->set_ioproxy(&memory) || !out->open(path.string(), spec) || !out->write_image(type, pixels) || !out->close())
    throw ImageError(fail + out->geterror());
  if (bytes.empty()) throw ImageError(fail + "the encoder produced no bytes");
  try {
    if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
    write_file_atomically(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  } catch (const std::exception& e) {  // AtomicWriteError or filesystem_error: say which file, and why
    throw ImageError(fail + e.what());
  }
}

}  // namespace desplat
