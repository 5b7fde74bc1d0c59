// report.html as desplat_train writes it: opened in a headless browser with every image and
// plot, and what structure from motion lost named in the log, metrics.json and the report.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "desplat/io/atomic_file.hpp"
#include "desplat/io/ply.hpp"
#include "desplat/sfm/subprocess.hpp"
#include "desplat/synth/synth.hpp"
#include "support/expect.hpp"
#include "support/scene_on_disk.hpp"
#include "support/synthetic_views.hpp"
#include "support/train_app.hpp"

namespace desplat::test {
namespace {

std::string decode_base64(const std::string& text) {
  std::string out;
  uint32_t buffer = 0;
  int bits = 0;
  for (char ch : text) {
    const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const char* p = std::strchr(alphabet, ch);
    if (ch == '=' || !p || ch == 0) continue;
    buffer = buffer << 6 | uint32_t(p - alphabet);
    bits += 6;
    if (bits >= 8) out += char(buffer >> (bits -= 8) & 0xff);
  }
  return out;
}

// report.html opened as a person would, in a real browser (Debian's Chromium, headless): every
// image decodes, every plot draws, and the screenshot is a page with pictures in it, not a
// blank or text-only one. The page's own script records what it found on <body>.
TEST_F(TrainApp, ReportOpensInHeadlessChromiumWithEveryImageAndPlot) {
  const fs::path out = root_ / "report_run";
  const Outcome r =
      run(train() + " --out " + out.string() + " --iterations 300 --threads 2 --eval-every 100 --effects distractors");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("report.html (open it in a browser)"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(out / "report.html"));
  EXPECT_FALSE(fs::exists(out / ".report_tmp"));  // gnuplot's files are cleaned up

  ASSERT_TRUE(find_executable("chromium")) << "chromium is not installed: run scripts/install_deps.sh";
  const std::string browser =
      "timeout 120 chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync --user-data-dir=" +
      (root_ / "chromium-profile").string() + " --virtual-time-budget=5000 ";
  const std::string url = "file://" + fs::absolute(out / "report.html").string();
  const Outcome dom = run(browser + "--dump-dom " + url);
  ASSERT_EQ(dom.exit_code, 0) << dom.output;
  // 2 test views + 14 training-view rows; the five curves (no full-resolution step in 300, so
  // no step-time chart).
  EXPECT_NE(dom.output.find("data-images=\"16\""), std::string::npos) << dom.output.substr(0, 2000);
  EXPECT_NE(dom.output.find("data-broken-images=\"0\""), std::string::npos);
  EXPECT_NE(dom.output.find("data-plots=\"5\""), std::string::npos);
  EXPECT_NE(dom.output.find("data-viewer=\"ok\""), std::string::npos);  // WebGL2 drew the model

  // The 3D viewer drew the static model from the first test view's camera: its first frame,
  // averaged over 15×15 blocks (960×720 → 64×48), against our CPU rasterizer's render of that
  // view in renders/test/ (right half). Same Gaussians, same projection; they differ by the
  // viewer's global sort (ours is per tile) and its 0.3 px² dilation at 15× the resolution.
  const Outcome frame_dom = run(browser + "--dump-dom " + url + "#viewer-frame");
  const std::string key = "data-viewer-frame=\"data:image/png;base64,";
  const size_t at = frame_dom.output.find(key);
  ASSERT_NE(at, std::string::npos) << frame_dom.output.substr(0, 500);
  const size_t end = frame_dom.output.find('"', at + key.size());
  write_file_atomically(root_ / "viewer.png",
                        decode_base64(frame_dom.output.substr(at + key.size(), end - at - key.size())));
  const FloatImage viewer = read_image_rgb(root_ / "viewer.png");
  ASSERT_EQ(viewer.width, 960);
  ASSERT_EQ(viewer.height, 720);
  const FloatImage side = read_image_rgb(out / "renders" / "test" / "view_0.png");  // the first test view
  const int w = side.width / 2, h = side.height;
  double mse = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        double mean = 0;
        for (int dy = 0; dy < 15; ++dy)
          for (int dx = 0; dx < 15; ++dx) mean += viewer.pixels[(size_t(y * 15 + dy) * 960 + x * 15 + dx) * 3 + c];
        const double d = mean / 225 - side.pixels[(size_t(y) * side.width + w + x) * 3 + c];
        mse += d * d;
      }
  const double viewer_psnr = -10 * std::log10(mse / (3.0 * w * h));
  std::printf("[   info   ] viewer's first frame against the CPU render: %.2f dB\n", viewer_psnr);
  // Measured 49.4 dB; a wrong projection, covariance, orientation or colour falls below 20, and
  // a wrong draw order of one Gaussian (the depth sort's bucket bug, fixed 2026-11-26) gave 27.3.
  EXPECT_GT(viewer_psnr, 35.0);

  const fs::path shot = root_ / "report.png";
  ASSERT_EQ(run(browser + "--window-size=1300,2600 --screenshot=" + shot.string() + " " + url).exit_code, 0);
  const FloatImage page = read_image_rgb(shot);
  ASSERT_EQ(page.width, 1300);
  std::set<uint32_t> colours;
  size_t coloured = 0;  // pixels that are not grey: plot lines, rendered images
  for (size_t p = 0; p < page.pixels.size() / 3; ++p) {
    uint32_t rgb24 = 0;
    float lo = 1, hi = 0;
    for (int c = 0; c < 3; ++c) {
      const float v = page.pixels[3 * p + c];
      rgb24 = rgb24 << 8 | uint32_t(std::lround(v * 255));
      lo = std::min(lo, v), hi = std::max(hi, v);
    }
    colours.insert(rgb24);
    coloured += hi - lo > 0.15f;
  }
  std::printf("[   info   ] screenshot: %zu colours, %zu coloured pixels\n", colours.size(), coloured);
  // A blank page has one colour and a text-only page a few dozen greys and no coloured pixel;
  // this one has the 3D view, the renders and the plots' lines, hundreds of thousands of
  // colours and coloured pixels (the printout says how many). The bounds sit far below that.
  EXPECT_GT(colours.size(), 1000u);
  EXPECT_GT(coloured, 5000u);
}

// desplat_train --images runs structure from motion first; here a stand-in `colmap` on PATH
// "finds" the scene's own model, which holds 16 of the 17 photos. What SfM lost, and every
// step it took, must reach the log, metrics.json and report.html.
TEST_F(TrainApp, PhotosStructureFromMotionLostAreNamedInLogMetricsAndReport) {
  const fs::path photos = root_ / "photos", bin = root_ / "fake_colmap_bin", out = root_ / "from_photos";
  fs::create_directories(photos);
  for (const auto& e : fs::directory_iterator(root_ / "scene" / "images"))
    fs::copy_file(e.path(), photos / e.path().filename());
  fs::copy_file(root_ / "scene" / "images" / "view_1.png", photos / "extra.png");  // a photo no model holds
  write_file_atomically(photos / "notes.txt", "not a photo");
  fs::create_directories(bin);
  const std::string fake =
      "#!/bin/sh\nprev=\"\"\nfor a in \"$@\"; do [ \"$prev\" = --output_path ] && out=\"$a\"; "
      "prev=\"$a\"; done\n[ \"$1\" = mapper ] && mkdir -p \"$out/0\" && cp " +
      (root_ / "scene" / "sparse" / "0").string() + "/* \"$out/0/\"\nexit 0\n";
  write_file_atomically(bin / "colmap", fake);
  fs::permissions(bin / "colmap", fs::perms::owner_all);
  const Outcome r = run("PATH=" + bin.string() + ":$PATH " + std::string(DESPLAT_TRAIN_BIN) + " --images " +
                        photos.string() + " --out " + out.string() + " --iterations 10 --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("colmap defaults:   16 of 17 photos"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("extra.png: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("notes.txt: not a photo"), std::string::npos) << r.output;
  nlohmann::json metrics;
  std::ifstream(out / "metrics.json") >> metrics;
  const nlohmann::json& sfm = metrics["sfm"];
  EXPECT_EQ(sfm["registered"], 16);
  EXPECT_EQ(sfm["photos"], 17);
  ASSERT_EQ(sfm["unregistered_photos"].size(), 1u);
  EXPECT_EQ(sfm["unregistered_photos"][0]["photo"], "extra.png");
  ASSERT_EQ(sfm["attempts"].size(), 1u);  // 16 of 17 is above 90 %: no escalation
  EXPECT_EQ(sfm["attempts"][0]["step"], "colmap defaults");
  EXPECT_EQ(sfm["warning"], "");
  EXPECT_EQ(sfm["matching"], "exhaustive: 17 photos are few enough to match every pair");
  const std::string report = desplat::testing::slurp(out / "report.html");
  EXPECT_NE(report.find("<h2>Structure from motion</h2>"), std::string::npos);
  EXPECT_NE(report.find("<tr><th>matching</th><td>exhaustive: 17 photos are few enough"), std::string::npos);
  // The stand-in wrote no database, so the reason is that it could not be read.
  EXPECT_EQ(sfm["unregistered_photos"][0]["reason"], "not in the model (colmap's database could not be read)");
  EXPECT_NE(report.find("<tr><th>extra.png</th><td>not in the model (colmap&#39;s database could not be read)"),
            std::string::npos);
  EXPECT_NE(report.find("<tr><th>notes.txt</th><td>not a photo"), std::string::npos);
  EXPECT_NE(report.find("<td>colmap defaults</td><td>16</td>"), std::string::npos);
  // The stages' times, as metrics.json has them (each under a minute with the stand-in: "4.2 s").
  const nlohmann::json& stages = sfm["stage_seconds"];
  auto seconds = [](const nlohmann::json& v) {
    EXPECT_LT(v.get<double>(), 59.0);
    char text[32];
    std::snprintf(text, sizeof text, "%.1f s", v.get<double>());
    return std::string(text);
  };
  const std::string times = "<tr><th>time by stage</th><td>features " + seconds(stages["extract"]) + ", matching " +
                            seconds(stages["match"]) + ", evidence " + seconds(stages["evidence"]) + ", mapping " +
                            seconds(stages["map"]) + "; " + seconds(sfm["seconds"]) + " in all</td>";
  EXPECT_NE(report.find(times), std::string::npos) << times;
  ASSERT_FALSE(sfm["mapper"].get<std::string>().empty());
  EXPECT_NE(report.find("<tr><th>mapper</th><td>"), std::string::npos);
}

}  // namespace
}  // namespace desplat::test
