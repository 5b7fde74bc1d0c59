// A fake `colmap` for the structure-from-motion tests (test_sfm*.cpp): a shell script placed
// first on PATH whose behaviour each test picks with environment variables, tiny photos, fake
// models, and the FakeColmap fixture that sets them up in a temporary folder.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "desplat/io/colmap.hpp"
#include "desplat/io/image_io.hpp"
#include "desplat/sfm/sfm.hpp"
#include "support/expect.hpp"
#include "support/scoped_env.hpp"
#include "support/temp_dir.hpp"

namespace desplat::testing::sfm_fixture {

namespace fs = std::filesystem;
namespace sfm = desplat::sfm;
namespace colmap = desplat::colmap;
using sfm::SfmErrorKind;

// Runs `o` and returns the SfmError it must throw.
inline sfm::SfmError expect_error(const sfm::SfmOptions& o, SfmErrorKind kind) {
  try {
    sfm::run_sfm(o);
  } catch (const sfm::SfmError& e) {
    EXPECT_EQ(static_cast<int>(e.kind()), static_cast<int>(kind)) << e.what();
    return e;
  }
  ADD_FAILURE() << "run_sfm did not throw";
  return sfm::SfmError(SfmErrorKind::BadOptions, "");
}

// ---- A fake colmap -----------------------------------------------------------------------

// Behaviour is picked with environment variables so each test sets only what it needs:
//   FAKE_COLMAP_ARGS file   append each command line to it
//   FAKE_COLMAP_FAIL stage  that stage prints an error and exits 3
//   FAKE_COLMAP_KILL stage  that stage kills itself with SIGKILL
//   FAKE_COLMAP_HANG stage  that stage sleeps for a minute
//   FAKE_COLMAP_DB file     feature_extractor copies it to --database_path
//   FAKE_COLMAP_MODELS dir  mapper copies dir/* into --output_path (the k-th mapper run copies
//                           dir.k/* instead when that exists, k = 2, 3, ...); otherwise mapper
//                           prints colmap's "failed to create sparse model" and exits
//                           $FAKE_COLMAP_NO_MODEL_EXIT (default 1, as colmap 3.8 does)
//   FAKE_COLMAP_REGISTERED dir  image_registrator copies dir/* into --output_path; otherwise it
//                           copies --input_path (registers nothing). bundle_adjuster does nothing.
inline const char* const kFakeColmap = R"SH(#!/bin/sh
stage="$1"
[ -n "$FAKE_COLMAP_ARGS" ] && echo "$*" >> "$FAKE_COLMAP_ARGS"
out=""
prev=""
for a in "$@"; do
  [ "$prev" = "--output_path" ] && out="$a"
  [ "$prev" = "--input_path" ] && in="$a"
  [ "$prev" = "--database_path" ] && db="$a"
  prev="$a"
done
case "$stage" in
  feature_extractor) echo "Processed file [1/3]"; echo "Processed file [3/3]" ;;
  *_matcher) printf "Matching block [1/1, 1/1]"; echo " in 0.1s" ;;
  mapper) echo "Initializing with image pair #1 and #2"; echo "Registering image #3 (3)" ;;
esac
if [ "$stage" = feature_extractor ] && [ -n "$FAKE_COLMAP_DB" ]; then cp "$FAKE_COLMAP_DB" "$db"; fi
if [ "$stage" = "$FAKE_COLMAP_FAIL" ]; then echo "fake colmap: disk on fire" >&2; exit 3; fi
if [ "$stage" = "$FAKE_COLMAP_KILL" ]; then kill -9 $$; fi
if [ "$stage" = "$FAKE_COLMAP_HANG" ]; then exec sleep 60; fi
if [ "$stage" = image_registrator ]; then cp -R "${FAKE_COLMAP_REGISTERED:-$in}"/. "$out"/; exit 0; fi
if [ "$stage" = mapper ]; then
  models="$FAKE_COLMAP_MODELS"
  k=$(grep -c '^mapper' "$FAKE_COLMAP_ARGS")
  [ -d "$models.$k" ] && models="$models.$k"
  if [ -n "$models" ] && [ -d "$models" ]; then cp -R "$models"/. "$out"/; exit 0; fi
  echo "ERROR: failed to create sparse model" >&2
  exit "${FAKE_COLMAP_NO_MODEL_EXIT:-1}"
fi
exit 0
)SH";

// "p3.png" (snprintf: GCC 12 warns falsely (-Wrestrict) about "p" + std::to_string(i)).
inline std::string photo_name(int i) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "p%d.png", i);
  return buf;
}

// A model whose images are photos[0..n).
inline colmap::Model fake_model(int n) {
  colmap::Model m;
  m.cameras[1] = colmap::Camera{1, colmap::CameraModelId::Pinhole, 16, 16, {20, 20, 8, 8}};
  for (int i = 0; i < n; ++i) {
    colmap::Image im;
    im.id = static_cast<uint32_t>(i + 1);
    im.camera_id = 1;
    im.tvec = {static_cast<double>(i), 0, 0};
    im.name = photo_name(i);
    m.images[im.id] = im;
  }
  return m;
}

inline void write_tiny_photos(const fs::path& dir, int n) {
  fs::create_directories(dir);
  desplat::FloatImage img{16, 16, 3, std::vector<float>(16 * 16 * 3, 0.5f)};
  for (int i = 0; i < n; ++i) desplat::write_image(dir / photo_name(i), img);
}

// A temp folder with 6 tiny photos, a fake colmap first on PATH, and options pointing there.
class FakeColmap : public ::testing::Test {
 protected:
  void SetUp() override {
    photos_ = tmp_.path() / "photos";
    write_tiny_photos(photos_, 6);
    const fs::path bin = tmp_.path() / "bin";
    fs::create_directories(bin);
    spit(bin / "colmap", kFakeColmap);
    fs::permissions(bin / "colmap", fs::perms::owner_all);
    path_.emplace("PATH", bin.string() + ":" + std::getenv("PATH"));
    args_log_ = tmp_.path() / "args.txt";
    args_env_.emplace("FAKE_COLMAP_ARGS", args_log_.string());
    options_.images = photos_;
    options_.out = tmp_.path() / "out";
    options_.on_progress = [this](const sfm::SfmProgress& p) { progress_.push_back(p); };
    options_.escalate = false;  // the escalation tests turn it on
  }
  // Models the fake mapper will "produce": one sub-folder per model, with these image counts.
  void give_models(std::initializer_list<int> sizes) {
    const fs::path dir = tmp_.path() / "models";
    int k = 0;
    for (int n : sizes) colmap::write_model_binary(fake_model(n), dir / std::to_string(k++));
    models_env_.emplace("FAKE_COLMAP_MODELS", dir.string());
  }

  TempDir tmp_;
  fs::path photos_, args_log_;
  std::optional<ScopedEnv> path_, args_env_, models_env_;
  sfm::SfmOptions options_;
  std::vector<sfm::SfmProgress> progress_;
};

}  // namespace desplat::testing::sfm_fixture
