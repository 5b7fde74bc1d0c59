// desplat_sfm: camera poses and a sparse point cloud for a folder of photos, by running
// colmap (CPU): feature extraction, matching, mapping. Writes the layout desplat_train reads.
// Options only; the job is desplat::run_sfm_job.
#include <CLI/CLI.hpp>

#include <string>

#include "desplat/jobs/sfm_run.hpp"

namespace {

namespace sfm = desplat::sfm;

const char* kDescription =
    "desplat_sfm: structure from motion for a folder of photos.\n"
    "\n"
    "Runs the colmap executable (3.8, CPU only) in three stages: feature_extractor (SIFT),\n"
    "a matcher, and mapper; shows one progress line per stage and keeps the model with the\n"
    "most registered photos. After matching it reads how the verified photo pairs move: a\n"
    "forward walk (most pairs moving along their viewing direction) is mapped from the first\n"
    "run with thresholds for forward motion and small angles. When fewer than 90 % of the photos\n"
    "are placed, it escalates, each step only if the one before fell short: the mapper again\n"
    "with relaxed thresholds; the photos left out registered into the model found; guided\n"
    "matching; twice the features. The last two match again, so they run only while a photo\n"
    "left out lacks verified matches; otherwise it stops and says what to try.\n"
    "Writes, under --out:\n"
    "  images/           symlink to --images (or a copy with --copy-images)\n"
    "  database.db       colmap's features and matches\n"
    "  sparse/0/         cameras.bin, images.bin, points3D.bin: the largest model\n"
    "                    (mapper's other models, if any, follow as sparse/1, ... by size)\n"
    "  colmap.log        everything colmap printed (follow it with tail -f)\n"
    "  image_list.txt    the photos handed to colmap\n"
    "  attempts/         each escalation step's models (and database when it matched again)\n"
    "Then run desplat_train on --out.\n";

const char* kFooter =
    "Photos: JPEG, PNG, TIFF, BMP, PPM/PGM, found recursively (hidden files skipped).\n"
    "\n"
    "Matchers:\n"
    "  auto        exhaustive for up to 100 photos (exhaustive matching costs O(n^2) pairs:\n"
    "              about 5 min for 50 photos of 540x960 on 2 cores); above that, sequential\n"
    "              when the photos look taken in file-name order (neighbours in name order\n"
    "              alike, judged from tiny thumbnails), exhaustive for a collection. The log\n"
    "              says which and why.\n"
    "  exhaustive  every pair of photos: the most robust\n"
    "  sequential  each photo with its 10 neighbours in file-name order (plus a few farther\n"
    "              ones): for video frames or photos taken walking along, named in order\n"
    "  spatial     pairs of photos whose EXIF GPS positions are close: drone or phone captures\n"
    "              with GPS; without GPS data nothing gets matched\n"
    "\n"
    "Camera models (COLMAP's): SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV,\n"
    "OPENCV_FISHEYE, FULL_OPENCV, FOV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE,\n"
    "THIN_PRISM_FISHEYE. By default OPENCV (fx, fy, cx, cy, 2 radial and 2 tangential\n"
    "distortion terms) when the photos share one camera, and SIMPLE_RADIAL (f, cx, cy, k)\n"
    "when each photo has its own (eight unknowns from one photo are too many); use\n"
    "OPENCV_FISHEYE for fisheye lenses.\n"
    "\n"
    "Exit status: 0 on success; 1 when structure from motion fails, with a message that says\n"
    "what to do; other non-zero values for a bad command line.\n";

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{kDescription, "desplat_sfm"};
  sfm::SfmOptions o;
  std::string matcher = "auto";
  std::string cameras = "auto";
  bool quiet = false;

  app.add_option("--images", o.images, "Folder of photos (read only; searched recursively)")->required();
  app.add_option("--out", o.out, "Output folder (created if missing)")->required();
  app.footer(kFooter);
  app.add_option("--matcher", matcher, "Which photo pairs to match (see Matchers below)")
      ->check(CLI::IsMember({"auto", "exhaustive", "sequential", "spatial"}))
      ->default_str("auto");
  app.add_option("--camera-model", o.camera_model,
                 "Camera model to calibrate (see Camera models below; default: OPENCV when the photos share "
                 "one camera, SIMPLE_RADIAL when each has its own)");
  app.add_option("--cameras", cameras,
                 "auto: one shared calibration when all photos have the same size and EXIF camera and focal "
                 "length, one per photo otherwise; single: always share one (one camera, one zoom); per-photo")
      ->check(CLI::IsMember({"auto", "single", "per-photo"}))
      ->default_str("auto");
  app.add_option("--min-registered-share", o.min_registered_share,
                 "Fail unless at least this share of the photos (and at least 3) end up in the model; a smaller "
                 "model is still kept in sparse/0. Below 0.9 placed, the run warns")
      ->check(CLI::Range(0.0, 1.0))
      ->default_str("0.5");
  app.add_flag("!--no-escalate", o.escalate,
               "Run colmap's default pipeline only, even when fewer than 90 % of the photos are placed (by "
               "default the escalation steps follow: relaxed mapper thresholds, registering the rest, guided "
               "matching, more features)");
  app.add_option("--threads", o.num_threads, "Threads colmap may use (-1: all cores)")->default_str("-1");
  app.add_flag("--copy-images", o.copy_images, "Copy the photos into <out>/images instead of a symlink to --images");
  app.add_flag("--overwrite", o.overwrite, "Replace database.db and sparse/ left in --out by an earlier run");
  app.add_option("--colmap", o.colmap, "The colmap executable: a name looked up on PATH, or a path")
      ->default_str("colmap");
  double stage_time_limit = 0;
  app.add_option("--stage-time-limit", stage_time_limit,
                 "Seconds each colmap stage may run before it is stopped (default: about ten times what it "
                 "needs on 2 cores for this many photos)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--quiet,-q", quiet, "No progress lines (errors and the summary are still printed)");
  CLI11_PARSE(app, argc, argv);

  o.matcher = *sfm::matcher_from_name(matcher);
  o.cameras = *sfm::camera_sharing_from_name(cameras);
  if (stage_time_limit > 0) o.stage_time_limit_s = stage_time_limit;
  return desplat::run_sfm_job(o, quiet);
}
