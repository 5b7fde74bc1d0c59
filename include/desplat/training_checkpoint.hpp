// Trainer state ⇄ Checkpoint (checkpoint.hpp): every parameter, Adam moment and
// densification statistic, the step, the view permutation and the RNG state, so that a
// restored trainer continues bit-exactly (for a fixed thread count).
#pragma once

#include "desplat/checkpoint.hpp"
#include "desplat/trainer.hpp"

namespace desplat {

Checkpoint make_training_checkpoint(const Trainer& trainer, const nlohmann::json& extra_metadata = {});
// Throws CheckpointError naming what does not fit (e.g. another SH degree).
void restore_training_checkpoint(Trainer& trainer, const Checkpoint& ckpt);
// The static Gaussians stored in a checkpoint (for rendering without a Trainer).
GaussianSet gaussians_from_checkpoint(const Checkpoint& ckpt);

}  // namespace desplat
