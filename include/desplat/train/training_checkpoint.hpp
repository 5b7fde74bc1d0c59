// Trainer state ⇄ Checkpoint (checkpoint.hpp): every parameter, Adam moment and
// densification statistic (static and every view's distractors), the step, the view permutation and the RNG state, so
// that a restored trainer continues bit-exactly (for a fixed thread count).
#pragma once

#include "desplat/io/checkpoint.hpp"
#include "desplat/train/trainer.hpp"

namespace desplat {

Checkpoint make_training_checkpoint(const Trainer& trainer, const nlohmann::json& extra_metadata = {});
// Throws CheckpointError naming what does not fit (e.g. another SH degree).
void restore_training_checkpoint(Trainer& trainer, const Checkpoint& ckpt);
// The static Gaussians stored in a checkpoint (for rendering without a Trainer).
GaussianSet gaussians_from_checkpoint(const Checkpoint& ckpt);
// The training views that own distractor buffers, in buffer order (empty: static-only model).
std::vector<std::string> distractor_views_in_checkpoint(const Checkpoint& ckpt);
// The training views of the appearance model's embeddings, in order (empty: no appearance).
std::vector<std::string> appearance_views_in_checkpoint(const Checkpoint& ckpt);
// The appearance model (throws CheckpointError for a model trained without one).
AppearanceModel appearance_from_checkpoint(const Checkpoint& ckpt);
// The training views of the background model's embeddings, in order (empty: no background model).
std::vector<std::string> background_views_in_checkpoint(const Checkpoint& ckpt);
// The background model (throws CheckpointError for a model trained without one).
BackgroundModel background_from_checkpoint(const Checkpoint& ckpt);
// The distractors of buffer `index` (an index into distractor_views_in_checkpoint).
GaussianSet distractors_from_checkpoint(const Checkpoint& ckpt, size_t index);

}  // namespace desplat
