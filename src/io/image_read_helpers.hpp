// Small helpers shared by src/io/distractor_masks.cpp (mask loading) and src/io/occluders.cpp
// (desplat_occlude). Internal to desplat; not installed.
#pragma once

#include <OpenImageIO/imageio.h>

#include <string>

namespace desplat::detail {

// "WxH", as error messages print image sizes.
inline std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// Open config that reads values as stored: by default OpenImageIO would multiply colour by a
// file's alpha channel.
inline OIIO::ImageSpec unassociated_alpha() {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  return config;
}

}  // namespace desplat::detail
