// Small helpers shared by the io layer's image readers (distractor masks, photo files).
// Private to the io layer.
#pragma once

#include <OpenImageIO/imageio.h>

#include <string>

namespace desplat {

// Open config that reads values as stored: by default OpenImageIO would multiply colour by a
// file's alpha channel.
inline OIIO::ImageSpec unassociated_alpha() {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  return config;
}

}  // namespace desplat
