#include "desplat/io/jpeg_end.hpp"

#include <fstream>
#include <iterator>
#include <stdexcept>
#include <vector>

namespace desplat {

bool jpeg_reaches_end_marker(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot read " + path.string());
  const std::vector<unsigned char> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (b.size() < 4 || b[0] != 0xFF || b[1] != 0xD8) return false;  // no start-of-image marker
  // Walk the marker segments up to the first scan: each is FF, a marker byte, and (except
  // for the stand-alone markers) a big-endian length that counts itself.
  size_t i = 2;
  while (true) {
    while (i < b.size() && b[i] != 0xFF) ++i;  // tolerate fill bytes between segments
    while (i < b.size() && b[i] == 0xFF) ++i;  // FF may repeat as padding
    if (i >= b.size()) return false;
    const unsigned char marker = b[i++];
    if (marker == 0xD9) return false;                                    // an end marker before any scan: no image
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no length
    if (i + 2 > b.size()) return false;
    const size_t length = size_t(b[i]) << 8 | b[i + 1];
    if (length < 2 || i + length > b.size()) return false;
    i += length;
    if (marker == 0xDA) break;  // start of scan: the entropy-coded data follows
  }
  for (; i + 1 < b.size(); ++i)
    if (b[i] == 0xFF && b[i + 1] == 0xD9) return true;
  return false;
}

}  // namespace desplat
