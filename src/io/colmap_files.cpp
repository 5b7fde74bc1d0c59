// Whole-file reads and writes for the COLMAP readers and writers, with errors that name the file.
#include "io/colmap_files.hpp"

#include <fstream>
#include <sstream>

#include "desplat/io/colmap.hpp"

namespace desplat::colmap {
namespace fs = std::filesystem;

std::string read_file(const fs::path& path) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status)) throw ColmapError(path.string() + ": file not found");
  if (!fs::is_regular_file(status)) throw ColmapError(path.string() + ": not a regular file");
  std::ifstream file(path, std::ios::binary);
  if (!file) throw ColmapError(path.string() + ": cannot open for reading");
  std::ostringstream bytes;
  bytes << file.rdbuf();
  if (file.bad() || bytes.bad()) throw ColmapError(path.string() + ": read error");
  return std::move(bytes).str();
}

void write_file(const fs::path& path, std::string_view bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) throw ColmapError(path.string() + ": cannot open for writing");
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();
  if (!file) throw ColmapError(path.string() + ": write error");
}

void make_directory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw ColmapError(dir.string() + ": cannot create directory: " + ec.message());
}

Model read_model(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw ColmapError(dir.string() + ": COLMAP model directory not found");
  if (fs::exists(ModelPaths::binary(dir).cameras, ec)) return read_model_binary(dir);
  if (fs::exists(ModelPaths::text(dir).cameras, ec)) return read_model_text(dir);
  throw ColmapError(dir.string() + ": no COLMAP model: neither " + ModelPaths::binary(dir).cameras.string() + " nor " +
                    ModelPaths::text(dir).cameras.string() + " exists");
}

}  // namespace desplat::colmap
