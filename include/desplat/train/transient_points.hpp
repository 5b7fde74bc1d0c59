// Which sparse points are on transient objects, and what initialization does with them
// (docs/METHOD.md §5, transient points). SfM triangulates whatever two or more photos agree
// on, so an object that stays for a few consecutive photos (a person, a hand) can leave
// points that would start as static Gaussians.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "desplat/comm/communicator.hpp"
#include "desplat/core/gaussians.hpp"
#include "desplat/train/training_data.hpp"

namespace desplat {

enum class TransientPointAction {
  keep,  // every point starts a static Gaussian (the authors' behaviour)
  drop,  // transient points are left out of the static initialization
  seed,  // … and each becomes a distractor in every training view that observes it
};
std::string to_string(TransientPointAction action);
// Throws std::invalid_argument naming the setting for anything but keep, drop or seed.
TransientPointAction transient_point_action_from_string(const std::string& text);

struct TransientPointSettings {
  // drop, the default: a transient point seeds a static Gaussian on the occluder
  // (docs/METHOD.md §5); --preset paper keeps, and the Trainer keeps every point when
  // distractors are off (the Splatfacto baseline).
  TransientPointAction action = TransientPointAction::drop;
  // A point whose track holds fewer images than this is transient: an object that stays for
  // one or two photos is in only those photos' tracks.
  int min_track_images = 3;
  // … or one whose colour at its projection in an observing training view differs from its
  // own (COLMAP's mean over the track) by more than this, mean |Δ| over RGB in [0, 1] units:
  // a point matched across photos that disagree is not one surface.
  float color_tolerance = 0.25f;
  // Compare after each view's exposure and white balance (train/effects.hpp, view_gains): the
  // point's colour times the view's gain. Photos taken at different exposures disagree with a
  // point's mean colour everywhere; without this a ±1-stop capture loses most of its points.
  // False: the colour as COLMAP stored it.
  bool per_view_gain = true;
};

// Per point of `data` (1 = transient), from data.point_track_images and data.point_train_views.
// A point without track information (both vectors empty: data not from a COLMAP model) is
// never transient. Colours are compared at the pixel the point projects into (Camera::pixel_of) in each
// observing training view, where it is in front of the camera and inside the image, against
// min(1, gain · colour) with the view's per-channel gain (per_view_gain) or the colour itself.
// In a job of several ranks (`comm`, collective) each view's evidence is judged on the rank
// holding its photo and every rank returns the same answer.
std::vector<uint8_t> transient_points(const TrainingData& data, const TransientPointSettings& settings,
                                      Communicator* comm = nullptr);

}  // namespace desplat
