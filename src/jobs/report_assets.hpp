// The style and scripts of report.html, kept as files in src/jobs/report_assets/ and embedded
// at build time: the build runs cmake/embed_files.cmake, which writes a source defining each
// view below over the file's bytes. Private to the jobs layer.
#pragma once

#include <string_view>

namespace desplat::assets {

extern const std::string_view report_css;            // report.css: the page's style
extern const std::string_view report_self_check_js;  // report_self_check.js: counts images and plots on load
extern const std::string_view splat_viewer_js;       // splat_viewer.js: the WebGL2 viewer (splat_viewer.hpp)

}  // namespace desplat::assets
