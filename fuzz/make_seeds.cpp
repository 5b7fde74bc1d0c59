// Writes seed corpora for the fuzz harnesses, using the project's own writers:
//   <out>/cameras, <out>/images, <out>/points3D   COLMAP .bin files
//   <out>/ply                                      3DGS PLY files
// Usage: fuzz_make_seeds <out> [<COLMAP sparse model dir to take a small real subset from>]
#include <cstdio>
#include <exception>
#include <filesystem>
#include <random>
#include <set>
#include <string>

#include "desplat/io/colmap.hpp"
#include "desplat/io/ply.hpp"
#include "fuzz_common.hpp"

namespace {

using namespace desplat;
namespace fs = std::filesystem;

// Writes `model` and files its three .bin files into the corpora as <name>.bin.
void add_model(const colmap::Model& model, const fs::path& out, const std::string& name) {
  const fuzz::ScratchDir scratch("seeds");
  colmap::write_model_binary(model, scratch.path());
  for (const char* file : {"cameras", "images", "points3D"})
    fs::copy_file(scratch.path() / (std::string(file) + ".bin"), out / file / (name + ".bin"),
                  fs::copy_options::overwrite_existing);
}

// One camera of every model COLMAP defines.
colmap::Model all_camera_models() {
  colmap::Model m;
  uint32_t id = 1;
  for (const colmap::CameraModelInfo& info : colmap::camera_models()) {
    colmap::Camera c{id, info.id, 320 + id, 240 + id, {}};
    for (int i = 0; i < info.num_params; ++i) c.params.push_back(i < 2 ? 300.0 + i : 0.01 * (i + 1));
    m.cameras[id++] = c;
  }
  return m;
}

// The first `n_images` images of a real model with at most `n_obs` observations each, and the
// parts of the points and cameras they use: still a consistent model, but a few KB.
colmap::Model subset(const colmap::Model& full, std::size_t n_images, std::size_t n_obs) {
  colmap::Model m;
  for (const auto& [id, image] : full.images) {
    if (m.images.size() == n_images) break;
    colmap::Image copy = image;
    if (copy.points2d.size() > n_obs) copy.points2d.resize(n_obs);
    m.images[id] = copy;
    m.cameras[image.camera_id] = full.cameras.at(image.camera_id);
  }
  for (const auto& [id, point] : full.points) {
    colmap::Point3D copy = point;
    std::erase_if(copy.track, [&](const colmap::TrackElement& el) {
      const auto it = m.images.find(el.image_id);
      return it == m.images.end() || el.point2d_idx >= it->second.points2d.size();
    });
    if (!copy.track.empty()) m.points[id] = copy;
  }
  for (auto& [id, image] : m.images)
    for (colmap::Observation& obs : image.points2d)
      if (obs.point3d_id != colmap::kNoPoint3D && !m.points.contains(static_cast<uint64_t>(obs.point3d_id)))
        obs.point3d_id = colmap::kNoPoint3D;
  return m;
}

void add_ply_seeds(const fs::path& dir) {
  std::mt19937 rng(1);
  std::normal_distribution<float> normal;
  for (int degree = 0; degree <= 3; ++degree) {
    for (std::size_t n : {std::size_t{0}, std::size_t{3}}) {
      GaussianSet g;
      g.sh_degree = degree;
      g.resize(n);
      for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.colors})
        for (float& v : *a) v = normal(rng);
      write_gaussian_ply(dir / ("sh" + std::to_string(degree) + "_n" + std::to_string(n) + ".ply"), g);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: %s <out dir> [<COLMAP sparse model dir>]\n", argv[0]);
    return 2;
  }
  try {
    const fs::path out = argv[1];
    for (const char* d : {"cameras", "images", "points3D", "ply"}) fs::create_directories(out / d);
    add_model(fuzz::small_model(), out, "small_model");
    add_model(colmap::Model{}, out, "empty_model");
    add_model(all_camera_models(), out, "all_camera_models");
    if (argc == 3) add_model(subset(colmap::read_model_binary(argv[2]), 3, 40), out, "real_subset");
    add_ply_seeds(out / "ply");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_make_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
