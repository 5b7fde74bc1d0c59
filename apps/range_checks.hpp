// Integer option checks for the apps whose message says what is allowed and what was given,
// in plain numbers ("must be at least 1 (got 0)"), instead of CLI11's range text.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

namespace desplat::apps {

// An integer in [lo, hi] (hi ≥ INT32_MAX reads "at least lo").
inline CLI::Validator integer_in(int64_t lo, int64_t hi) {
  const std::string allowed = hi >= INT32_MAX ? "at least " + std::to_string(lo)
                                              : "an integer in " + std::to_string(lo) + ".." + std::to_string(hi);
  return CLI::Validator(
      [lo, hi, allowed](std::string& text) -> std::string {
        size_t used = 0;
        long long v = 0;
        try {
          v = std::stoll(text, &used);
        } catch (const std::exception&) {
          return "must be " + allowed + " (got '" + text + "')";
        }
        if (used != text.size() || v < lo || v > hi) return "must be " + allowed + " (got " + text + ")";
        return {};
      },
      allowed);
}

}  // namespace desplat::apps
