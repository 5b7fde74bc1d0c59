// CRC-32 as used by zlib, gzip and PNG (IEEE 802.3 polynomial, reflected 0xEDB88320, initial
// value and final xor 0xFFFFFFFF). Internal to desplat; defined in src/io/checkpoint.cpp.
#pragma once

#include <cstddef>
#include <cstdint>

namespace desplat::detail {

// Continues `crc` (the result of a previous call, 0 to start) over n more bytes, so
// crc32_update(crc32_update(0, a), b) is the CRC of a followed by b.
// crc32_update(0, "123456789", 9) == 0xCBF43926.
std::uint32_t crc32_update(std::uint32_t crc, const void* data, std::size_t n);

}  // namespace desplat::detail
