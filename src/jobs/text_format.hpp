// Numbers and durations as text for the jobs' printed lines and report.html. Private to the
// jobs layer.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace desplat {

// `v` with `decimals` digits after the point ("32.59").
inline std::string fixed(double v, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, v);
  return text;
}

enum class DurationStyle {
  // For sentences and tables: "4.2 s" below a minute, "2 min 05 s", "1 h 01 min" (rounded to
  // the second); "n/a" when the value is not a number.
  words,
  // For the progress line, fixed width: "0m04s", "2m05s", "1h01m" (whole seconds, truncated;
  // negative and non-finite values count as 0).
  compact,
};

// A wall time in seconds as a person reads it.
inline std::string format_duration(double seconds, DurationStyle style = DurationStyle::words) {
  char text[48];
  if (style == DurationStyle::compact) {
    const long t = std::isfinite(seconds) ? long(std::max(0.0, seconds)) : 0;
    if (t >= 3600)
      std::snprintf(text, sizeof text, "%ldh%02ldm", t / 3600, t / 60 % 60);
    else
      std::snprintf(text, sizeof text, "%ldm%02lds", t / 60, t % 60);
    return text;
  }
  if (!std::isfinite(seconds)) return "n/a";
  const long t = std::lround(seconds);
  if (t >= 3600)
    std::snprintf(text, sizeof text, "%ld h %02ld min", t / 3600, t / 60 % 60);
  else if (t >= 60)
    std::snprintf(text, sizeof text, "%ld min %02ld s", t / 60, t % 60);
  else
    std::snprintf(text, sizeof text, "%.1f s", seconds);
  return text;
}

}  // namespace desplat
