// libFuzzer harness for one JSON reader, chosen at build time by DESPLAT_FUZZ_JSON:
// "config" (--config text: parse_json_bounded + config_from_json), "scene" (a desplat_synth
// scene description: load_description) or "grid" (a desplat_bench grid: read_bench_grid).
//
// Contract checked: the reader returns or throws std::invalid_argument / std::runtime_error
// (SynthError, JsonTextError) with a message; anything
// else (another exception, a crash, a sanitizer report, a stack overflow on deep nesting, a
// hang) is a finding. A config that is accepted must survive its own JSON round trip.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "desplat/io/json_text.hpp"
#include "desplat/jobs/bench_run.hpp"
#include "desplat/synth/synth.hpp"
#include "desplat/train/train_config_json.hpp"
#include "fuzz_common.hpp"

#ifndef DESPLAT_FUZZ_JSON
#error "define DESPLAT_FUZZ_JSON as config, scene or grid"
#endif

namespace {

using namespace desplat;

const std::string kReader = DESPLAT_FUZZ_JSON;

struct Scratch {
  fuzz::ScratchDir dir{"json-" + kReader};
  std::filesystem::path input = dir.path() / "input.json";
};

Scratch& scratch() {
  static Scratch s;
  return s;
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "finding: %s\n", what.c_str());
  std::abort();
}

void read_config(const std::string& text) {
  const nlohmann::json j = parse_json_bounded(text, "--config text");
  const TrainConfig c = config_from_json(j, TrainConfig{});
  // Accepted: its own record reads back to the same settings.
  if (!config_differences(c, config_from_json(config_to_json(c), TrainConfig{}), "round trip").empty())
    finding("an accepted config does not survive config_to_json / config_from_json");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    if (kReader == "config") {
      read_config(text);
    } else {
      fuzz::write_input(scratch().input, data, size);
      if (kReader == "scene")
        (void)synth::load_description(scratch().input);
      else
        (void)read_bench_grid(scratch().input);
    }
  } catch (const std::invalid_argument&) {
  } catch (const std::runtime_error&) {  // SynthError
  } catch (const nlohmann::json::exception&) {
    // A value of the wrong type that a reader passed on unwrapped: a poor message, not a crash.
  } catch (const std::exception& e) {
    finding(std::string("unexpected exception type: ") + e.what());
  }
  return 0;
}
