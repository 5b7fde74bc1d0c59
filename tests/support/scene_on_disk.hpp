// Writes TrainingData as a scene folder in the layout users bring: images/*.png and a
// binary COLMAP sparse/0 with PINHOLE cameras (one shared camera) and the points.
#pragma once

#include <Eigen/Geometry>
#include <filesystem>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat::test {

inline void write_scene_folder(const std::filesystem::path& dir, const TrainingData& data) {
  colmap::Model model;
  const Camera& c0 = data.train.at(0).camera;
  model.cameras[1] = {1,
                      colmap::CameraModelId::Pinhole,
                      uint64_t(c0.width),
                      uint64_t(c0.height),
                      {double(c0.fx), double(c0.fy), double(c0.cx), double(c0.cy)}};
  uint32_t id = 1;
  for (const auto* list : {&data.train, &data.test})
    for (const TrainView& v : *list) {
      write_image(dir / "images" / (v.name + ".png"), to_float(v.image));
      Eigen::Matrix3d R;
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) R(r, k) = v.camera.R_cw[3 * r + k];
      const Eigen::Quaterniond q(R);
      colmap::Image im;
      im.id = id;
      im.qvec_wxyz = {q.w(), q.x(), q.y(), q.z()};
      im.tvec = {v.camera.t_cw[0], v.camera.t_cw[1], v.camera.t_cw[2]};
      im.camera_id = 1;
      im.name = v.name + ".png";
      model.images[id] = im;
      ++id;
    }
  for (size_t i = 0; i < data.points.size(); ++i) {
    colmap::Point3D p;
    p.id = i + 1;
    p.xyz = {data.points[i][0], data.points[i][1], data.points[i][2]};
    p.rgb = data.colors[i];
    p.error = 0;
    model.points[p.id] = p;
  }
  std::filesystem::create_directories(dir / "sparse" / "0");
  colmap::write_model_binary(model, dir / "sparse" / "0");
}

}  // namespace desplat::test
