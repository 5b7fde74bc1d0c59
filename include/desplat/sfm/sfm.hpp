// Structure from motion for a folder of photos, by running the `colmap` 3.8 executable
// (CPU only): feature_extractor → exhaustive/sequential/spatial matcher → the capture evidence
// (CaptureEvidence: the mapper's thresholds for a forward walk) → mapper, then, when fewer than
// kEscalateBelowShare of the photos are placed, the escalation steps below (the two that match
// again only while a photo left out lacks verified matches).
//
// Output layout (what the rest of desplat reads), under SfmOptions::out:
//   images/          a symlink to the input folder (absolute target; the input may be
//                    read-only), or a copy with copy_images; left alone when the input already
//                    is <out>/images
//   database.db      colmap's feature and match database
//   sparse/0/        {cameras,images,points3D}.bin: the model with the most registered images;
//                    mapper's other models (if any) follow as sparse/1, sparse/2, … by size
//   colmap.log       everything colmap printed, stage by stage, with each command line
//   image_list.txt   the photos handed to colmap (names relative to images/)
//   attempts/        escalation steps, one folder each ("1-relaxed-mapper", ...) with their
//                    models (and database.db when the step matched again); when a step's model
//                    wins, its models and database trade places with sparse/ and database.db
//
// Failures are SfmError with one message that says what went wrong and what to do. A run
// never leaves a child process behind and cannot block on colmap's output; colmap killed by
// a signal is reported like a non-zero exit.
//
// Thread safety: run_sfm only touches files under `out`; concurrent runs need distinct `out`.
// It reads PATH at call time, and needs SIGCHLD not to be ignored (to read colmap's exit status).
// colmap runs without a shell (paths need no quoting), stdin from /dev/null, default signal
// dispositions; Ctrl-C reaches it through the terminal's process group and is reported as
// "killed by signal 2".
#pragma once

#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "desplat/core/image.hpp"
#include "desplat/sfm/subprocess.hpp"

namespace desplat::sfm {

enum class SfmErrorKind {
  BadOptions,        // e.g. unknown camera model, min_registered_share outside (0, 1]
  ColmapMissing,     // the executable is not on PATH (or not executable)
  BadImages,         // images folder missing, empty, or without readable images; too few photos
  OutputExists,      // earlier results in `out` and overwrite is off, or `out` unusable
  StageFailed,       // a colmap stage could not start, exited non-zero or was killed by a signal
  TimedOut,          // a colmap stage ran past its time limit and was stopped
  NoModel,           // the mapper produced no model
  TooFewRegistered,  // the best model holds fewer than the required share of photos (it is kept)
};

class SfmError : public std::runtime_error {
 public:
  SfmError(SfmErrorKind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  SfmErrorKind kind() const { return kind_; }

 private:
  SfmErrorKind kind_;
};

enum class Matcher { Auto, Exhaustive, Sequential, Spatial };

// Auto: exhaustive for up to this many photos; above it, sequential when the photos were taken
// in file-name order (judge_capture_order), exhaustive otherwise. Exhaustive matching costs
// O(n²) image pairs, so its time grows with the square of the photos and soon dominates the
// run; sequential matching (each photo against its 10 neighbours in file-name order, plus
// quadratic overlap) is linear in n, but it only pairs
// photos that are near each other in name order, so on a shuffled collection it matches
// almost nothing. colmap's vocabulary-tree matcher would be the linear choice for a large
// collection, but it needs a trained tree file that Debian's colmap does not ship.
inline constexpr int kExhaustiveMaxImages = 100;

// "auto", "exhaustive", "sequential", "spatial" (exact); nullopt otherwise.
std::optional<Matcher> matcher_from_name(const std::string& name);
const char* matcher_name(Matcher matcher);
// Auto resolved for `num_images` photos that were (`photos_in_order`) or were not taken in
// file-name order; any other value is returned unchanged.
Matcher choose_matcher(Matcher requested, int num_images, bool photos_in_order);

// ---- Ordered frames or an unordered collection ----------------------------------------------
//
// A photo in a capture taken in order (video frames, a walk around an object) shares most of
// its view with the photos named next to it; in a collection, or a capture whose names do not
// follow it, a neighbour in name order is as unlike it as any other photo. So: each photo
// becomes a tiny colour thumbnail, each channel normalized to zero mean and unit variance
// (exposure, gain and white balance do not count), and the median distance between neighbours
// in name order is compared with the median distance between photos half the capture apart.
// Without order both medians sample the same distribution (ratio ≈ 1).
inline constexpr int kOrderThumbnailSize = 8;  // cells per side: the coarse layout of the view
inline constexpr int kOrderThumbnailValues = 3 * kOrderThumbnailSize * kOrderThumbnailSize;  // RGB planes
// Two thumbnails are compared at the best of the shifts of up to this many cells each way: a
// camera that moved a little sees the same things a little moved across the frame.
inline constexpr int kOrderMaxShift = 1;
// Ordered when neighbours are at most this fraction as far apart as photos half the capture
// apart. Shuffled captures sit near 1 (the two medians sample one distribution), with less
// spread the more photos there are; the bar sits well below that because the two mistakes do
// not cost the same: an ordered capture taken for a collection is
// matched exhaustively (slower, every pair still found), a collection taken for ordered frames
// is matched sequentially and loses the pairs far apart in name order.
inline constexpr double kOrderedDistanceRatio = 0.8;

struct CaptureOrder {
  bool ordered = false;
  // Median RMS difference of the thumbnails (each pair at its best shift): of neighbours in
  // name order, and of photos half the capture apart.
  double neighbour_distance = 0, far_distance = 0;
  std::string reason;  // for the log
};

// The thumbnail of an image: kOrderThumbnailValues floats, three planes (R, G, B; a grey image
// gives the same plane thrice) of kOrderThumbnailSize² box-filtered cells, row-major, each plane
// normalized to zero mean and unit variance; the aspect ratio is not kept. A flat plane is zeros.
std::vector<float> order_thumbnail(const FloatImage& image);
// The judgement for thumbnails in file-name order; needs at least 4 (fewer: not ordered).
// std::invalid_argument when a thumbnail is not kOrderThumbnailValues long.
CaptureOrder judge_capture_order(const std::vector<std::vector<float>>& thumbnails);
// Reads the photos (relative to `dir`, in file-name order) and judges them. A photo that cannot
// be decoded counts as a flat image.
CaptureOrder detect_capture_order(const std::filesystem::path& dir, const std::vector<std::filesystem::path>& photos);

// Photos a model must hold for a run to succeed: max(3, ⌈share·n⌉) of n photos. The default
// share, one half: fewer than half placed means the capture mostly failed, and training on the
// rest would drop most of the user's photos. Three is the least a model can be trusted with.
inline constexpr double kDefaultMinRegisteredShare = 0.5;
int required_registered(double share, int num_images);

// Below this share of placed photos run_sfm escalates (SfmOptions::escalate), and a result
// below it carries a warning: a tenth of the photos lost is a tenth less model.
inline constexpr double kEscalateBelowShare = 0.9;

// ---- What the verified matches say about the capture ------------------------------------------
//
// After matching, run_sfm reads colmap's database (every geometrically verified pair: its inlier
// matches and fundamental or essential matrix) and recovers each pair's relative motion
// (src/sfm/two_view_evidence.hpp): how much of it is along the viewing direction and under
// which angles the pair sees its points. colmap's default mapper starts a model only from a pair with at
// least kColmapInitMinInliers inliers whose baseline lies more than acos(0.95) ≈ 18° off the
// viewing direction and whose points are seen under kColmapInitMinTriAngleDeg; it keeps only
// points seen under 1.5°. Walking forward (a street, a corridor, video from a car or a drone
// flying ahead) moves every camera along its own viewing direction, so its well-matched pairs
// fail that start test and the points ahead, near the direction of travel, are seen under tiny
// angles: the matches are there and the mapper refuses them.

// colmap 3.8's default mapper thresholds the rule is stated against.
inline constexpr int kColmapInitMinInliers = 100;  // Mapper.init_min_num_inliers
inline constexpr double kColmapInitMaxForwardMotion =
    0.95;                                                // Mapper.init_max_forward_motion, |t_z| of the unit baseline
inline constexpr double kColmapInitMinTriAngleDeg = 16;  // Mapper.init_min_tri_angle
// A photo colmap can place needs this many 2D–3D inliers (Mapper.abs_pose_min_num_inliers), and
// those come from its verified matches: a photo with fewer than kPlaceableMinPartners partners
// holding that many inliers lacks matches; one with more was matched and the mapper refused it.
inline constexpr int kPlaceableInliers = 30;
inline constexpr int kPlaceableMinPartners = 2;
// The forward-walk rule: a capture is a forward walk when at least this share of its strong
// pairs (≥ kColmapInitMinInliers inliers, a relative pose recovered) move within 18° of the
// viewing direction. Then most of the pairs colmap's defaults would start from and grow with are
// the ones they refuse; in an orbit or a collection the share sits near 0 (sideways baselines).
inline constexpr double kForwardPairShare = 0.5;

struct CaptureEvidence {
  bool read = false;                          // false: the database could not be read for it (`summary` says why)
  int photos = 0;                             // photos in the database
  int verified_pairs = 0;                     // pairs with at least one inlier match
  int strong_pairs = 0;                       // ≥ kColmapInitMinInliers inliers and a relative pose recovered
  int forward_pairs = 0;                      // strong pairs whose baseline is within 18° of the viewing direction
  int default_start_pairs = 0;                // strong pairs colmap's defaults may start from (not forward, ≥ 16°)
  double median_partners = 0;                 // verified partners per photo (median over photos)
  int max_inliers = 0;                        // the largest inlier count of any pair
  double median_forward_angle_deg = 0;        // angle between baseline and viewing direction, median over strong pairs
  double median_neighbour_tri_angle_deg = 0;  // per photo: the median triangulation angle of its
                                              // strongest pair; median over photos
  int sequential_photos = 0;                  // photos whose strongest partner is at most 2 names away
  int poorly_matched_photos = 0;              // fewer than kPlaceableMinPartners partners with kPlaceableInliers
  bool forward = false;                       // is_forward_capture
  std::string summary;                        // one line for the log and metrics.json
};

// The rule above: read, strong_pairs > 0 and forward_pairs ≥ kForwardPairShare · strong_pairs.
bool is_forward_capture(const CaptureEvidence& evidence);

// How photos are given cameras (intrinsics). Auto: one shared camera when every photo has the
// same size and the same EXIF make, model and focal length (or none of them), one per photo
// otherwise (choose_cameras).
enum class CameraSharing { Auto, Single, PerPhoto };
const char* camera_sharing_name(CameraSharing sharing);  // "auto", "single", "per-photo"
std::optional<CameraSharing> camera_sharing_from_name(const std::string& name);

// What a photo file says about its camera (what colmap's image reader also reads).
struct PhotoCamera {
  int width = 0, height = 0;  // px
  std::string make, model;    // EXIF; empty when not recorded
  float focal_mm = 0;         // EXIF focal length; 0 when not recorded
};

struct CameraChoice {
  bool single = false;  // one calibration shared by all photos
  std::string reason;   // for the log: what was decided and why
};
CameraChoice choose_cameras(CameraSharing requested, const std::vector<PhotoCamera>& cameras);

// The camera model when the user names none: OPENCV (fx, fy, cx, cy, k1, k2, p1, p2) for one
// shared camera, which every photo constrains; SIMPLE_RADIAL (f, cx, cy, k, colmap's own
// default) for one camera per photo, where eight intrinsics from one photo's matches are too
// many for colmap to place the photo reliably.
const char* auto_camera_model(bool single_camera);

enum class SfmStage { Extract, Match, Map };

// Seconds a stage may take before it is taken for hung: about ten times what a stage needs on
// a small CPU machine, so only a stuck colmap reaches it, plus a fixed margin for start-up.
// Extract 300 + 30·n; exhaustive matching 600 + 3·n(n−1)/2 (3 s per image pair), other
// matchers 600 + 60·n; mapping 600 + 60·n (n photos).
double default_stage_time_limit(SfmStage stage, Matcher matcher, int num_photos);

// One progress report. `done`/`total` count images (extraction), blocks or images (matching,
// see `unit`), or registered photos of the model being built (mapping; total = all photos).
struct SfmProgress {
  SfmStage stage = SfmStage::Extract;
  int done = 0;
  int total = 0;          // 0 when not known yet
  int model = 1;          // mapping: 1-based index of the model being built
  const char* unit = "";  // "image", "block"
  bool finished = false;  // the stage's last report
};

// "extracting features: image 12/50", "matching: block 3/7", "mapping: registered 31/50 photos".
std::string describe(const SfmProgress& progress);

using ProgressFn = std::function<void(const SfmProgress&)>;

// A ProgressFn for a terminal: on a TTY it rewrites one line in place (at most ~10 times a
// second); otherwise it prints plain lines, at most one per `plain_interval_s` per stage plus each
// stage's last one. `out` must outlive the returned function.
ProgressFn terminal_progress(std::FILE* out, bool is_tty, double plain_interval_s = 5.0);

struct SfmOptions {
  std::filesystem::path images;  // folder of photos (searched recursively; read only)
  std::filesystem::path out;     // created if missing
  Matcher matcher = Matcher::Auto;
  // Any COLMAP camera model name (colmap.hpp); empty: auto_camera_model of the camera choice.
  std::string camera_model;
  CameraSharing cameras = CameraSharing::Auto;
  // Fail (TooFewRegistered, the model kept) when the best model holds fewer photos than
  // required_registered(share, photos found); in (0, 1].
  double min_registered_share = kDefaultMinRegisteredShare;
  // Run the escalation steps (run_sfm) when fewer than kEscalateBelowShare of the photos are placed.
  bool escalate = true;
  int num_threads = -1;           // colmap's: -1 = all cores
  bool copy_images = false;       // copy the photos into <out>/images instead of a symlink
  bool overwrite = false;         // replace database.db, sparse/ and the log of an earlier run
  std::string colmap = "colmap";  // executable: a name looked up on PATH, or a path
  // Seconds each colmap stage may run before it is stopped (SfmErrorKind::TimedOut); must be
  // > 0. nullopt: default_stage_time_limit for the stage and the number of photos.
  std::optional<double> stage_time_limit_s;
  ProgressFn on_progress;  // may be empty
};

// A file or photo that was left out, and why (path relative to the images folder).
struct SkippedFile {
  std::filesystem::path path;
  std::string reason;  // "empty file (0 bytes)", "the JPEG is truncated (...)", ...
};

// One try at placing the photos: the first run, or an escalation step.
struct SfmAttempt {
  std::string step;      // "colmap defaults", "relaxed mapper", "register the rest", ...
  std::string settings;  // the colmap options it changed
  int registered = 0;    // photos in its largest model (0: no model)
  int points = 0;        // 3D points in that model
  double seconds = 0;    // wall time of the step
};

struct SfmResult {
  std::filesystem::path images_dir;       // <out>/images
  std::filesystem::path sparse_dir;       // <out>/sparse/0
  std::filesystem::path database;         // <out>/database.db
  std::filesystem::path log;              // <out>/colmap.log
  Matcher matcher = Matcher::Exhaustive;  // as resolved
  std::string matcher_reason;             // why (for the log): "exhaustive: 50 photos, ..."
  CameraChoice cameras;                   // as resolved, with its reason
  std::vector<SfmAttempt> attempts;       // the first run, then each escalation step, in order
  std::string warning;                    // non-empty when fewer than kEscalateBelowShare are placed
  int num_photos = 0;                     // readable photos found and handed to colmap
  std::vector<SkippedFile> skipped;       // files in the images folder that were not photos colmap can use
  // Photos handed to colmap that sparse/0 does not hold, each with the reason the other models
  // and colmap's database give (a separate model; too few features; no verified match; matched
  // but not placeable).
  std::vector<SkippedFile> unregistered;
  double mean_track_length = 0;        // images per 3D point of sparse/0
  double mean_reprojection_error = 0;  // px, colmap's per-point error averaged over sparse/0
  int num_registered = 0;              // photos in sparse/0
  int num_points = 0;                  // 3D points in sparse/0
  int num_models = 0;                  // models mapper wrote
  double seconds = 0;                  // wall time of the whole run
  double extract_seconds = 0, match_seconds = 0, map_seconds = 0;  // wall time of each stage
  double evidence_seconds = 0;                                     // reading the capture evidence from the database
  CaptureEvidence capture;    // what the verified matches say (read after matching)
  std::string mapper_reason;  // which mapper thresholds the first run used, and why
  // Non-empty when the escalation stopped before its last step because the evidence says the
  // remaining steps cannot help: why, and what to try instead.
  std::string escalation_stopped;
};

// What a run left out, for a person: one line per skipped file with its reason and the names of
// the photos colmap could not place, at most `max_names` names per list ("… and N more").
// Empty when nothing was lost.
std::string describe_lost_photos(const SfmResult& result, size_t max_names = 20);

// How the photos were placed, for a person: the camera choice and its reason, then one line per
// attempt ("colmap defaults: 30 of 44 photos, 1189 points, 114 s (one shared camera, ...)", an
// example of the format),
// then the warning if any.
std::string describe_attempts(const SfmResult& result);

// Runs the whole pipeline; see the file comment for the layout and errors.
SfmResult run_sfm(const SfmOptions& options);

// The images folder sorted into photos colmap can be given and files it cannot. Photos: regular
// files under `dir` (recursive, hidden entries skipped) with an image extension that OpenImageIO
// opens, with pixels, and (JPEG) not truncated. Paths relative to `dir`, sorted. SfmError
// (BadImages) when `dir` is missing or not a folder (an empty folder is not an error here).
struct PhotoScan {
  std::vector<std::filesystem::path> photos;
  std::vector<PhotoCamera> cameras;  // of each photo, in the same order
  std::vector<SkippedFile> skipped;
};
PhotoScan scan_photos(const std::filesystem::path& dir);

using desplat::find_executable;  // subprocess.hpp

}  // namespace desplat::sfm
