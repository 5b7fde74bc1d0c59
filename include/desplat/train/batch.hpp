// A step over a batch of B training views (docs/METHOD.md §6, batches): the rules that make
// one B-view step stand for B single-view steps, after Grendel-GS (Zhao et al., ICLR 2025).
// Step indices here count views seen: a batch covers the views [first, first + B).
#pragma once

#include <cstdint>
#include <functional>
#include <span>

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

// The order in which a batch's per-view values are summed (docs/METHOD.md §6, ranks), the view
// tree: the entries whose view index is even are summed, the odd ones are summed, then the two
// sums are added, recursively on the index's next bit; entries of one view index are added in
// draw order. `views` are the entries' view indices in draw order; add(into, from) adds entry
// `from`'s value into entry `into`'s. Returns the entry that holds the sum (−1 when empty).
// The order does not depend on the rank count: with N ranks a power of two, rank r holds the
// views ≡ r mod N, a subtree of its own, and the communicator's rank tree (communicator.hpp)
// adds those subtrees as this tree does, so N ranks and one process add the same floats in
// the same order.
int sum_in_view_tree(std::span<const int> views, const std::function<void(int into, int from)>& add);

// sum += g over every parameter group's gradient (kParamGroupTable); the shapes must agree.
// Element by element, so the result does not depend on the thread count.
void add_gradients(RasterGradients& sum, const RasterGradients& g);

}  // namespace desplat
