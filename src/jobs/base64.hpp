// Base64 (RFC 4648, with padding) for data: URLs and data blocks inlined in report.html.
// Private to the jobs layer.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace desplat {

inline std::string base64(const void* data, size_t size) {
  static const char* const k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const auto* bytes = static_cast<const uint8_t*>(data);
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  for (size_t i = 0; i < size; i += 3) {
    const uint32_t v = uint32_t(bytes[i]) << 16 | (i + 1 < size ? uint32_t(bytes[i + 1]) << 8 : 0) |
                       (i + 2 < size ? uint32_t(bytes[i + 2]) : 0);
    out += k[v >> 18 & 63];
    out += k[v >> 12 & 63];
    out += i + 1 < size ? k[v >> 6 & 63] : '=';
    out += i + 2 < size ? k[v & 63] : '=';
  }
  return out;
}

inline std::string base64(const std::string& bytes) { return base64(bytes.data(), bytes.size()); }

}  // namespace desplat
