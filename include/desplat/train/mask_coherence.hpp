// The distractor mask's coherence prior (docs/METHOD.md §4, ours): total variation of the
// distractor layer's alpha A_d. A transient object covers a connected area, and part of it
// often matches the scene behind it (on the occluded fox, 16 % of occluder pixels are within
// 0.1 of the clean photo). The photometric loss cannot tell who should explain such a pixel;
// this prior gives it to the layer that explains its neighbours, so the mask fills the
// object instead of leaving holes, and costs nothing where A_d is flat (a clean view).
// Also the occluder-colour prior: where a distractor is, it should be opaque and show the
// photo's colour, so a mask does not stop at the least alpha that fits.
#pragma once

#include <span>

#include "desplat/raster/composite.hpp"

namespace desplat {

// λ · Σ |A(p) − A(q)| over horizontally and vertically adjacent pixel pairs p, q, divided by
// the number of (kept) pixels. `alpha` is [height·width], row-major. ADDS the gradient to
// `d_alpha` [height·width] (sign(A(p) − A(q)) · λ / pixels to p, its negative to q; zero for
// equal values) and returns the value. With `keep` ([height·width], 0 or 1, the user's mask)
// a pair counts only when both pixels are kept, and the mean runs over kept pixels.
double mask_total_variation(std::span<const float> alpha, int width, int height, float lambda, std::span<float> d_alpha,
                            std::span<const float> keep = {});

// The occluder-colour prior (docs/METHOD.md §4, ours): a transient object is opaque and shows
// what the photo shows. λ · mean over (kept) pixels of (1/3) Σ_c |C_d(p,c) − A_d(p)·I(p,c)|,
// C_d the distractor layer's premultiplied colour [P·3], A_d its alpha [P], I `target` [P·3].
// Where the composite fits the photo over a static colour s this equals (1 − A_d)·|I − s|:
// a half-transparent distractor of an extreme colour (the least alpha that fits, which leaves
// masks partial) pays for the static layer's whole miss, an opaque one of the photo's colour
// pays nothing. Against λ_d·A_d a distractor turns opaque where the miss exceeds λ_d / λ and
// fades where it is smaller. ADDS the gradient (the sign of each term) to d_color [P·3] and
// d_alpha [P] and returns the value; with `keep` ([P], 0 or 1) the mean runs over kept pixels
// and ignored ones get no gradient.
double occluder_colour_prior(Layer distractor, std::span<const float> target, float lambda, std::span<float> d_color,
                             std::span<float> d_alpha, std::span<const float> keep = {});

}  // namespace desplat
