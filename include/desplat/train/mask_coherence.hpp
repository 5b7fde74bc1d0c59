// The distractor mask's coherence prior (docs/METHOD.md §4, ours): total variation of the
// distractor layer's alpha A_d. A transient object covers a connected area, and part of it
// often matches the scene behind it (on the occluded fox, 16 % of occluder pixels are within
// 0.1 of the clean photo). The photometric loss cannot tell who should explain such a pixel;
// this prior gives it to the layer that explains its neighbours, so the mask fills the
// object instead of leaving holes, and costs nothing where A_d is flat (a clean view).
#pragma once

#include <span>

namespace desplat {

// λ · Σ |A(p) − A(q)| over horizontally and vertically adjacent pixel pairs p, q, divided by
// the number of (kept) pixels. `alpha` is [height·width], row-major. ADDS the gradient to
// `d_alpha` [height·width] (sign(A(p) − A(q)) · λ / pixels to p, its negative to q; zero for
// equal values) and returns the value. With `keep` ([height·width], 0 or 1, the user's mask)
// a pair counts only when both pixels are kept, and the mean runs over kept pixels.
double mask_total_variation(std::span<const float> alpha, int width, int height, float lambda,
                            std::span<float> d_alpha, std::span<const float> keep = {});

}  // namespace desplat
