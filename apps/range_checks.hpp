// Integer option checks for the apps whose message states the whole allowed range and what was
// given, in plain numbers ("must be an integer in [1, 64] (got 1000)"), instead of CLI11's text.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

namespace desplat::apps {

// An integer in [lo, hi], written in digits.
inline CLI::Validator integer_in(int64_t lo, int64_t hi) {
  const std::string allowed = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  return CLI::Validator(
      [lo, hi, allowed](std::string& text) -> std::string {
        size_t used = 0;
        long long v = 0;
        bool parsed = true;
        try {
          v = std::stoll(text, &used);
        } catch (const std::out_of_range&) {
          return "must be " + allowed + " (got " + text + ")";
        } catch (const std::exception&) {
          parsed = false;
        }
        if (!parsed || used != text.size()) return "must be " + allowed + ", written in digits (got '" + text + "')";
        if (v < lo || v > hi) return "must be " + allowed + " (got " + text + ")";
        return {};
      },
      allowed);
}

}  // namespace desplat::apps
