// libFuzzer harness for the checkpoint reader past its checksums: restoring a training
// checkpoint into a run. A tiny DeSplat run (three 24x24 views) writes a valid checkpoint once;
// each input then changes it and the changed checkpoint is written with valid CRCs, so the
// reader's framing checks pass and restore_training_checkpoint meets the content itself.
//   input[0] even: input[1..] is a JSON merge patch for the metadata (e.g. {"step": -5});
//   input[0] odd:  input[1..] is a list of 8-byte edits (array index, element, 32-bit value)
//                  applied to the arrays' elements.
//
// Contract checked: restoring returns or throws CheckpointError; anything else (another
// exception, a crash, a sanitizer report) is a finding. A restored run must take a step
// without crashing.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "desplat/io/checkpoint.hpp"
#include "desplat/io/json_text.hpp"
#include "desplat/train/training_checkpoint.hpp"
#include "fuzz_common.hpp"

namespace {

using namespace desplat;

TrainingData tiny_data() {
  TrainingData d;
  for (int v = 0; v < 3; ++v) {
    TrainView view;
    view.name = "v" + std::to_string(v) + ".png";
    view.camera.fx = view.camera.fy = 30;
    view.camera.cx = view.camera.cy = 12;
    view.camera.width = view.camera.height = 24;
    view.camera.t_cw = {0.1f * float(v), 0, 3};
    view.image = {24, 24, 3, std::vector<uint8_t>(24 * 24 * 3, uint8_t(60 + 40 * v))};
    d.train.push_back(view);
  }
  for (int p = 0; p < 30; ++p) {
    d.points.push_back({0.05f * float(p % 5) - 0.1f, 0.05f * float(p / 5) - 0.15f, 0.1f * float(p % 3)});
    d.colors.push_back({uint8_t(8 * p), 100, 200});
  }
  return d;
}

TrainConfig tiny_config() {
  TrainConfig c;
  c.iterations = 10;
  c.num_downscales = 0;
  c.sh_degree = 1;
  c.threads = 1;
  c.distractors.initial_count = 10;
  c.distractors.reference_pixels = 0;
  return c;
}

struct Fixture {
  fuzz::ScratchDir scratch{"checkpoint"};
  std::filesystem::path file = scratch.path() / "checkpoint.ckpt";
  TrainingData data = tiny_data();
  TrainConfig config = tiny_config();
  Checkpoint base;
  Fixture() {
    Trainer t(data, config);
    for (int i = 0; i < 2; ++i) t.step();
    base = make_training_checkpoint(t);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "finding: %s\n", what.c_str());
  std::abort();
}

// Applies the input to a copy of the base checkpoint; false when the input is not usable.
bool changed(const std::uint8_t* data, std::size_t size, Checkpoint& c) {
  if (size == 0) return false;
  c = fixture().base;
  if (data[0] % 2 == 0) {
    nlohmann::json patch;
    try {
      patch = parse_json_bounded(std::string(reinterpret_cast<const char*>(data + 1), size - 1), "patch");
    } catch (const std::exception&) {
      return false;
    }
    c.metadata.merge_patch(patch);
    return c.metadata.is_object();
  }
  std::vector<std::string> names;
  for (const auto& [name, a] : c.arrays) names.push_back(name);
  for (std::size_t at = 1; at + 8 <= size; at += 8) {
    std::uint16_t which;
    std::uint16_t element;
    std::uint32_t value;
    std::memcpy(&which, data + at, 2);
    std::memcpy(&element, data + at + 2, 2);
    std::memcpy(&value, data + at + 4, 4);
    const std::string& name = names[which % names.size()];
    const CheckpointArray& a = c.arrays.at(name);
    if (a.size() == 0 || a.byte_size() / a.size() != 4) continue;  // float32 and int32 only
    const CheckpointArray::Shape shape = a.shape();
    if (a.holds<float>()) {
      std::vector<float> v = a.values<float>();
      std::memcpy(&v[element % v.size()], &value, 4);
      c.put(name, shape, std::move(v));
    } else {
      std::vector<std::int32_t> v = a.values<std::int32_t>();
      std::memcpy(&v[element % v.size()], &value, 4);
      c.put(name, shape, std::move(v));
    }
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Fixture& f = fixture();
  Checkpoint c;
  if (!changed(data, size, c)) return 0;
  try {
    write_checkpoint(f.file, c);  // valid CRCs around whatever the input made
  } catch (const CheckpointError&) {
    return 0;  // the writer refuses it (e.g. metadata that does not round-trip)
  }
  Trainer t(f.data, f.config);
  try {
    restore_training_checkpoint(t, read_checkpoint(f.file));
  } catch (const CheckpointError&) {
    return 0;  // the documented way to refuse a checkpoint
  } catch (const std::exception& e) {
    finding(std::string("restoring threw something other than CheckpointError: ") + e.what());
  }
  try {
    t.step();
  } catch (const std::exception&) {
    // A step may refuse what a finite but absurd restored value leads to; it must not crash.
  }
  return 0;
}
