// A step over a batch of B training views (docs/METHOD.md §6, batches): the rules that make
// one B-view step stand for B single-view steps, after Grendel-GS (Zhao et al., ICLR 2025).
// Step indices here count views seen: a batch covers the views [first, first + B).
#pragma once

#include <cstdint>

#include "desplat/raster/raster.hpp"
#include "desplat/train/param_groups.hpp"

namespace desplat {

// The static rates of a B-view step: every rate × √B (Grendel's square-root rule: B summed
// independent gradients move Adam's normalized step like √B single-view steps). `lr` itself
// when views is 1.
LearningRates batch_learning_rates(LearningRates lr, int views);

// The view index in [first, first + views) at which a schedule firing at the multiples of
// `every` fires, or −1 when none falls in the batch; with views ≤ every at most one does.
// A schedule's event at view t happens after the step of the batch holding t.
int64_t batch_event(int64_t first, int views, int64_t every);

// sum += g over every parameter group's gradient (kParamGroupTable); the shapes must agree.
// Element by element, so the result does not depend on the thread count.
void add_gradients(RasterGradients& sum, const RasterGradients& g);

}  // namespace desplat
