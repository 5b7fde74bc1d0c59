// Numbers as text for the jobs' printed lines and report.html. Private to the jobs layer.
#pragma once

#include <cstdio>
#include <string>

namespace desplat {

// `v` with `decimals` digits after the point ("32.59").
inline std::string fixed(double v, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, v);
  return text;
}

}  // namespace desplat
