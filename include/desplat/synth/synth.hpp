// Synthetic scenes with known ground truth: a textured static world of planes, boxes
// and spheres, photographed along an orbit, a forward-facing path or a forward walk (cameras
// looking ahead as they move, as a street walk is photographed), written in the layout a
// user brings (images/ + a binary COLMAP sparse/0) plus what no real capture has: the clean
// image of every view and the distractor mask of every training view.
//
// Output layout of generate_scene (names are zero-padded view indices, "0000.png", …):
//   <out>/images/<name>.png            every view as the camera recorded it: training views with
//                                      distractors, exposure/white balance and noise as described;
//                                      test views never have distractors
//   <out>/clean/<name>.png             static scene only (no distractors, exposure, white balance
//                                      or noise), every view
//   <out>/distractor_masks/<name>.png  every training view: 8-bit grey, 255 where distractors cover
//                                      the majority of the pixel's samples, else 0 (all 0 when the
//                                      view is uncluttered); none for test views
//   <out>/sparse/0/{cameras,images,points3D}.bin   binary COLMAP model (colmap.hpp), one camera
//   <out>/train_list.txt, test_list.txt            one image name per line
//   <out>/scene.json                               the effective description (all defaults filled)
// Test views are exactly those of the default split (splits.hpp EveryNth, 8): view k is a test
// view when k % 8 == 0, so `desplat_train --data <out>` needs no split options.
//
// Frames and units: the world is right-handed with z up, in "world units" (the scene is a few
// units across). Camera poses follow COLMAP (docs/METHOD.md §1): p_cam = R·p_world + t, camera
// looking along +z, x right, y down. Pixel (i, j) has its center at (i + 0.5, j + 0.5); a
// pixel of a distorted camera sees the ray camera_from_image (camera_models.hpp) gives for it.
// Colors are in [0, 1] and written as 8-bit PNG without a transfer curve.
//
// Description files (JSON): every key is optional (defaults below); unknown keys are errors.
// "base": "other.json" (relative to the file) loads that description first and applies this
// file on top; keys may be dotted ("distractors.clutter_ratio": 0.4 sets one field). Arrays
// (e.g. "world.objects") replace the base's array as a whole. data/synthetic/README.md lists
// the format with an example.
//
// Determinism: the output is a pure function of the description (seed included): the same
// description gives byte-identical files for any thread count.
//
// Errors: SynthError. Description problems name the file and the key ("…/a.json: key
// 'camera.width': must be an integer ≥ 8, got 3"); output problems name the path.
// Ownership and threads: plain value types; functions have no shared state.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace desplat::synth {

struct SynthError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

using Rgb = std::array<double, 3>;    // [0, 1]
using Vec3d = std::array<double, 3>;  // world units

// A procedural solid texture, evaluated at the 3D world position of a surface point.
struct TextureSpec {
  std::string kind = "noise";  // "solid" (color_a), "checker", "stripes", "noise" (fBm blend)
  Rgb color_a{0.8, 0.8, 0.8};
  Rgb color_b{0.3, 0.3, 0.3};
  double scale = 4;     // pattern cells per world unit
  double detail = 0.3;  // fBm modulation of brightness on top of the pattern, [0, 1]
  friend bool operator==(const TextureSpec&, const TextureSpec&) = default;
};

struct ObjectSpec {
  std::string shape = "box";  // "plane" (finite rectangle), "box", "sphere"
  Vec3d center{0, 0, 0};
  Vec3d size{1, 1, 1};    // box: full extents along its axes; plane: extents along its two tangent
                          // axes (size[2] unused); sphere: unused (radius)
  double radius = 0.5;    // sphere only
  Vec3d normal{0, 0, 1};  // plane only: its normal (need not be unit length)
  double yaw_deg = 0;     // box and plane: rotation about the world z axis (box) or the normal (plane)
  TextureSpec texture;
  friend bool operator==(const ObjectSpec&, const ObjectSpec&) = default;
};

struct CameraSpec {
  int width = 64, height = 48;                      // [px]
  double fov_x_deg = 60;                            // horizontal field of view of the pinhole part; fy = fx
  std::array<double, 2> principal_offset_px{0, 0};  // principal point − image center [px]
  std::string model = "PINHOLE";                    // "PINHOLE" or "OPENCV"
  std::array<double, 4> distortion{0, 0, 0, 0};     // OPENCV only: k1, k2, p1, p2
  friend bool operator==(const CameraSpec&, const CameraSpec&) = default;
};

struct ViewsSpec {
  int count = 8;                           // all views; every 8th (k % 8 == 0) is a test view
  std::string path = "orbit";              // "orbit", "forward" or "walk"
  Vec3d target{0, 0, 0.3};                 // orbit, forward: every camera looks at this point; walk: the
                                           // ground point below the middle of the walk
  double radius = 4;                       // orbit: horizontal distance to the target's axis; forward:
                                           // distance from the path's centre to the target; walk: its length
  double height = 2.5;                     // camera height above the target (world z)
  double arc_deg = 360;                    // orbit: the arc the cameras span (360: a closed circle)
  double start_deg = 0;                    // azimuth of the first camera (orbit), of the path (forward) or of
                                           // the direction of walking (walk)
  std::array<double, 2> spread{1.0, 0.5};  // forward: half-extents of the camera path (spiral); walk: the
                                           // amplitudes of its sideways sway and vertical bob
  double position_jitter = 0;              // uniform random offset of each camera centre [world units]
  friend bool operator==(const ViewsSpec&, const ViewsSpec&) = default;
};

struct LightSpec {
  Vec3d direction{0.4, 0.3, 1.0};  // towards the light (need not be unit length)
  double ambient = 0.35;           // share of light that reaches every surface
  friend bool operator==(const LightSpec&, const LightSpec&) = default;
};

// The default world: a textured ground plane, two boxes and a sphere around the origin.
std::vector<ObjectSpec> default_world_objects();

struct WorldSpec {
  std::vector<ObjectSpec> objects = default_world_objects();  // at least one
  LightSpec light;
  Rgb background{0.55, 0.6, 0.65};  // color of rays that miss everything (without a sky)
  friend bool operator==(const WorldSpec&, const WorldSpec&) = default;
};

// Effects: each one is off by default and costs nothing when off.
struct SkySpec {  // a sky at infinity (depends on the ray direction only) instead of background
  bool enabled = false;
  Rgb horizon{0.75, 0.82, 0.9};
  Rgb zenith{0.25, 0.45, 0.8};
  double clouds = 0.5;  // cloud cover [0, 1]
  friend bool operator==(const SkySpec&, const SkySpec&) = default;
};

struct DistractorSpec {                    // per-view objects in front of the static scene, training views only
  double clutter_ratio = 0;                // share of training views with distractors: round(ratio · #train),
                                           // spread evenly over the training views in name order
  std::array<int, 2> per_view{1, 3};       // min, max objects in a cluttered view
  std::array<double, 2> size{0.15, 0.35};  // object diameter as a fraction of the image height
  std::array<double, 2> depth{0.3, 0.55};  // distance from the camera as a fraction of its distance
                                           // to the point it looks at (walk: views.radius ahead)
  int track_length = 1;                    // runs of this many consecutive training views show the same objects at
                                           // the same place in the frame (they move with the camera, as a hand or a
                                           // strap would), which no single 3D position explains; 1 = independent views
  friend bool operator==(const DistractorSpec&, const DistractorSpec&) = default;
};

struct ExposureSpec {        // per-view gain and white balance, training views (and test views if asked)
  double stops = 0;          // gain 2^u, u uniform in [−stops, stops]
  double white_balance = 0;  // per-channel factor 1 + u, u uniform in [−wb, wb]
  bool test_views = false;
  friend bool operator==(const ExposureSpec&, const ExposureSpec&) = default;
};

struct NoiseSpec {  // sensor noise: Gaussian, variance sigma² + shot·value, per pixel and channel
  double sigma = 0;
  double shot = 0;
  bool test_views = true;
  friend bool operator==(const NoiseSpec&, const NoiseSpec&) = default;
};

struct PointsSpec {                   // points3D.bin: surface points seen by the views, as SfM would give them
  int count = 2000;                   // points sampled (those seen by < min_track views are dropped)
  double position_noise_px = 0.3;     // 3D noise, σ chosen to reproject to this many pixels
  double observation_noise_px = 0.1;  // noise of the stored 2D observations [px]
  int min_track = 2;
  friend bool operator==(const PointsSpec&, const PointsSpec&) = default;
};

struct Description {
  uint64_t seed = 1;
  CameraSpec camera;
  ViewsSpec views;
  int supersampling = 2;  // s × s jittered samples per pixel (1–4)
  WorldSpec world;
  SkySpec sky;
  DistractorSpec distractors;
  ExposureSpec exposure;
  NoiseSpec noise;
  PointsSpec points;
  friend bool operator==(const Description&, const Description&) = default;
};

// Reads a description file (following "base" files), fills defaults and checks every value.
Description load_description(const std::filesystem::path& file);
// Applies `patch` (same format as a file, "base" not allowed) on top of `base`; `source` names
// it in error messages. Checks the result.
Description apply_description(const Description& base, const nlohmann::json& patch, const std::string& source);
// Every field, as load_description reads it back.
nlohmann::json description_to_json(const Description& description);

struct GenerateOptions {
  std::filesystem::path out;                            // created if missing
  bool overwrite = false;                               // replace an earlier generator output in `out` (only its files)
  std::function<void(const std::string&)> on_progress;  // one line per stage; empty: silent
};

// What the generator did; the effect counters are 0 for effects the description leaves off.
struct GenerationReport {
  int num_train = 0, num_test = 0;
  std::vector<std::string> cluttered_views;  // names of the training views with distractors
  size_t num_points = 0, num_observations = 0;
  uint64_t distractor_ray_tests = 0;  // rays tested against distractors
  uint64_t sky_evaluations = 0;
  uint64_t exposure_pixels = 0, noise_pixels = 0;
  double seconds = 0, render_seconds = 0, points_seconds = 0, write_seconds = 0;
};

// Writes the scene (layout at the top). Throws SynthError when `out` holds other files (a
// non-empty folder without a scene.json) or, without `overwrite`, an earlier output; and when a
// cluttered view ends up with an empty mask (distractors hidden by static geometry).
GenerationReport generate_scene(const Description& description, const GenerateOptions& options);

// The image name of view k ("0000.png") and whether it is a test view.
std::string view_name(int k, int count);
bool is_test_view(int k);

}  // namespace desplat::synth
