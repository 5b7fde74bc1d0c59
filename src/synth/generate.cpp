// generate_scene: lays out the views, renders each, applies the requested effects, samples
// the sparse points and writes the capture layout of synth.hpp.
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>

#include "desplat/synth/synth.hpp"

#include "desplat/core/stopwatch.hpp"
#include "synth/camera_path.hpp"
#include "synth/distractors.hpp"
#include "synth/photo_effects.hpp"
#include "synth/sparse_points.hpp"
#include "synth/view_render.hpp"

namespace desplat::synth {
namespace {

namespace fs = std::filesystem;

// What an earlier run wrote; --overwrite removes exactly these.
const std::vector<std::string> kOutputs{"images",         "clean",         "distractor_masks", "sparse",
                                        "train_list.txt", "test_list.txt", "scene.json"};

void prepare_output(const GenerateOptions& o) {
  std::error_code ec;
  if (fs::exists(o.out) && !fs::is_directory(o.out)) throw SynthError(o.out.string() + ": exists and is not a folder");
  if (fs::is_directory(o.out) && !fs::is_empty(o.out)) {
    if (!fs::exists(o.out / "scene.json"))
      throw SynthError(o.out.string() +
                       ": folder is not empty and holds no generated scene (no scene.json); "
                       "choose an empty or new folder");
    if (!o.overwrite)
      throw SynthError(o.out.string() + ": holds an earlier generated scene; pass --overwrite to replace it");
    for (const auto& name : kOutputs) fs::remove_all(o.out / name, ec);
    if (ec) throw SynthError((o.out / "?").string() + ": cannot remove the earlier output: " + ec.message());
  }
  for (const char* sub : {"images", "clean", "distractor_masks", "sparse/0"}) {
    fs::create_directories(o.out / sub, ec);
    if (ec) throw SynthError((o.out / sub).string() + ": cannot create the folder: " + ec.message());
  }
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  if (!f.flush()) throw SynthError(path.string() + ": cannot write the file");
}

// Writes the files concurrently (PNG compression is a large share of the generator's time).
void write_pngs(const std::vector<std::pair<fs::path, const FloatImage*>>& files) {
  std::string error;
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t i = 0; i < files.size(); ++i) {
    try {
      write_image(files[i].first, *files[i].second);
    } catch (const std::exception& e) {
#pragma omp critical
      if (error.empty()) error = e.what();
    }
  }
  if (!error.empty()) throw SynthError(error);
}

colmap::Image colmap_image(int k, int count, const ViewPose& pose) {
  colmap::Image image;
  image.id = static_cast<uint32_t>(k + 1);
  image.camera_id = 1;
  image.name = view_name(k, count);
  glm::dmat3 R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R[c][r] = pose.R_cw(r, c);
  const glm::dquat q = quaternion_of(R);
  image.qvec_wxyz = {q.w, q.x, q.y, q.z};
  image.tvec = {pose.t_cw.x(), pose.t_cw.y(), pose.t_cw.z()};
  return image;
}

}  // namespace

std::string view_name(int k, int count) {
  const int digits = std::max(4, static_cast<int>(std::to_string(count - 1).size()));
  std::string number = std::to_string(k);
  return std::string(static_cast<size_t>(std::max(0, digits - static_cast<int>(number.size()))), '0') + number + ".png";
}

bool is_test_view(int k) { return k % 8 == 0; }  // splits.hpp EveryNth with 8, names sorted = k order

GenerationReport generate_scene(const Description& d, const GenerateOptions& o) {
  const Stopwatch t0;
  const auto progress = [&](const std::string& line) {
    if (o.on_progress) o.on_progress(line);
  };
  prepare_output(o);
  write_text(o.out / "scene.json", description_to_json(d).dump(2) + "\n");

  const colmap::Camera lens = make_lens(d.camera);
  const std::vector<ViewPose> poses = camera_path(d.views, d.seed);
  std::vector<Primitive> statics;
  for (const auto& object : d.world.objects) statics.push_back(make_primitive(object));
  StaticScene scene{Primitives(std::move(statics), d.world.light), d.world, d.sky};

  const int n = d.views.count;
  const std::vector<bool> cluttered = cluttered_views(n, d.distractors.clutter_ratio);
  std::vector<Primitives> distractors(static_cast<size_t>(n));
  int train_index = 0, track_first = 0;  // a track's views draw from its first training view's stream
  for (int k = 0; k < n; ++k) {
    if (is_test_view(k)) continue;
    if (train_index++ % d.distractors.track_length == 0) track_first = k;
    if (cluttered[static_cast<size_t>(k)])
      distractors[static_cast<size_t>(k)] = Primitives(
          make_distractors(d.distractors, poses[static_cast<size_t>(k)], lens, d.seed, track_first), d.world.light);
  }

  GenerationReport report;
  const bool exposure_on = d.exposure.stops > 0 || d.exposure.white_balance > 0;
  const bool noise_on = d.noise.sigma > 0 || d.noise.shot > 0;
  const Stopwatch t_render;
  const SampleGrid grid = make_sample_grid(lens, d.supersampling, d.seed);
  std::string train_list, test_list;
  for (int k = 0; k < n; ++k) {
    const std::string name = view_name(k, n);
    const bool test = is_test_view(k);
    ViewRender r = render_view(scene, distractors[static_cast<size_t>(k)], poses[static_cast<size_t>(k)], grid);
    report.distractor_ray_tests += r.distractor_ray_tests;
    report.sky_evaluations += r.sky_evaluations;
    // The recorded photo: distractors, then the camera's gain, then its noise.
    const bool exposure = exposure_on && (!test || d.exposure.test_views);
    const bool noise = noise_on && (!test || d.noise.test_views);
    const uint64_t pixels = static_cast<uint64_t>(r.clean.width) * r.clean.height;
    FloatImage changed;  // only when the photo differs from the clean image
    if (r.cluttered) changed = std::move(*r.cluttered);
    if ((exposure || noise) && !r.cluttered) changed = r.clean;
    if (exposure) {
      apply_gain(changed, exposure_gain(d.exposure, d.seed, k));
      report.exposure_pixels += pixels;
    }
    if (noise) {
      add_sensor_noise(changed, d.noise, d.seed, k);
      report.noise_pixels += pixels;
    }
    const FloatImage& photo = changed.pixels.empty() ? r.clean : changed;
    const Stopwatch t_write;
    std::vector<std::pair<fs::path, const FloatImage*>> files{{o.out / "clean" / name, &r.clean},
                                                              {o.out / "images" / name, &photo}};
    if (!test) files.emplace_back(o.out / "distractor_masks" / name, &r.mask);
    write_pngs(files);
    report.write_seconds += t_write.seconds();
    if (cluttered[static_cast<size_t>(k)]) {
      if (std::none_of(r.mask.pixels.begin(), r.mask.pixels.end(), [](float m) { return m > 0; }))
        throw SynthError("view " + name +
                         ": its distractors cover no pixel (hidden by static geometry); "
                         "lower distractors.depth or raise distractors.size");
      report.cluttered_views.push_back(name);
    }
    (test ? test_list : train_list) += name + "\n";
    (test ? report.num_test : report.num_train) += 1;
    progress("rendered " + name + " (" + std::to_string(k + 1) + "/" + std::to_string(n) + ")");
  }
  report.render_seconds = t_render.seconds() - report.write_seconds;
  write_text(o.out / "train_list.txt", train_list);
  write_text(o.out / "test_list.txt", test_list);

  const Stopwatch t_points;
  colmap::Model model;
  model.cameras[1] = lens;
  for (int k = 0; k < n; ++k)
    model.images[static_cast<uint32_t>(k + 1)] = colmap_image(k, n, poses[static_cast<size_t>(k)]);
  add_sparse_points({&scene.objects, &distractors, &poses, lens, d.points, d.seed}, model);
  report.num_points = model.points.size();
  for (const auto& [id, p] : model.points) report.num_observations += p.track.size();
  report.points_seconds = t_points.seconds();
  progress("sampled " + std::to_string(report.num_points) + " points");
  try {
    colmap::write_model_binary(model, o.out / "sparse" / "0");
  } catch (const colmap::ColmapError& e) {
    throw SynthError(e.what());
  }
  report.seconds = t0.seconds();
  return report;
}

}  // namespace desplat::synth
