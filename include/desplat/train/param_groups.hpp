// The trainable parameter groups, declared once. The optimizer, the checkpoint format, the
// non-finite scan and the gradient tests all iterate this table, so adding a group is one entry
// here plus its math (forward, vector–Jacobian product, and a Jet test).
//
// Every group is a row-aligned array of the Gaussian set (row i = Gaussian i, `width` floats
// per row) with a gradient array of the same shape in RasterGradients. Static and distractor
// buffers use the same groups; they differ only in colour layout (SH for static, RGB for
// distractors), in whether they carry appearance features (static only, when the appearance
// model is on; otherwise the group has zero width) and in their learning rates
// (TrainConfig::lr, DistractorSettings::lr).
#pragma once

#include <array>
#include <vector>

#include "desplat/core/gaussians.hpp"
#include "desplat/raster/raster.hpp"

namespace desplat {

enum class ParamGroup { Means = 0, LogScales, Quats, OpacityLogits, Colors, Features };
inline constexpr int kParamGroups = 6;

// Learning rate per group (docs/METHOD.md §6); for Colors in SH mode the DC coefficient uses
// `colors_dc` and the higher bands `colors_rest` (in RGB mode `colors_dc` applies to all three).
// The means' rate follows an exponential schedule that the trainer applies (TrainConfig).
struct LearningRates {
  float means = 1.6e-4f, log_scales = 5e-3f, quats = 1e-3f, opacity_logits = 5e-2f;
  float colors_dc = 2.5e-3f, colors_rest = 1.25e-4f;
  float features = 5e-3f;  // the appearance model's per-Gaussian embeddings (the paper's appendix)
};

// ParamGroupInfo::width's two layouts that depend on the set.
inline constexpr int kColorLayout = 0;     // GaussianView::color_floats_per_gaussian()
inline constexpr int kFeatureLayout = -1;  // GaussianSet::feature_dim

struct ParamGroupInfo {
  ParamGroup id;
  const char* name;                            // checkpoint arrays "<buffer>/<name>", messages
  int width;                                   // floats per Gaussian, or kColorLayout / kFeatureLayout
  std::vector<float> GaussianSet::*values;     // [N, width]
  std::vector<float> RasterGradients::*grads;  // [N, width] ∂L/∂values
  float LearningRates::*rate;                  // Colors: the DC (or RGB) rate
};

inline constexpr std::array<ParamGroupInfo, kParamGroups> kParamGroupTable{{
    {ParamGroup::Means, "means", 3, &GaussianSet::means, &RasterGradients::means, &LearningRates::means},
    {ParamGroup::LogScales, "log_scales", 3, &GaussianSet::log_scales, &RasterGradients::log_scales,
     &LearningRates::log_scales},
    {ParamGroup::Quats, "quats", 4, &GaussianSet::quats, &RasterGradients::quats, &LearningRates::quats},
    {ParamGroup::OpacityLogits, "opacity_logits", 1, &GaussianSet::opacity_logits, &RasterGradients::opacity_logits,
     &LearningRates::opacity_logits},
    {ParamGroup::Colors, "colors", kColorLayout, &GaussianSet::colors, &RasterGradients::colors,
     &LearningRates::colors_dc},
    {ParamGroup::Features, "features", kFeatureLayout, &GaussianSet::features, &RasterGradients::features,
     &LearningRates::features},
}};

inline const ParamGroupInfo& param_group(ParamGroup g) { return kParamGroupTable[static_cast<size_t>(g)]; }

// Floats per Gaussian of group `info` in a set with this colour layout.
inline int group_width(const ParamGroupInfo& info, const GaussianSet& set) {
  if (info.width == kColorLayout) return set.view().color_floats_per_gaussian();
  if (info.width == kFeatureLayout) return set.feature_dim;
  return info.width;
}

}  // namespace desplat
