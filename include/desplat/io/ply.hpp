// Standard 3D Gaussian Splatting PLY files (docs/METHOD.md §9), the format read by the
// original 3DGS code, gsplat/nerfstudio exporters and the common web viewers.
//
// File layout: "ply", "format binary_little_endian 1.0", "element vertex N", then one
// `property float` line per value and "end_header\n", followed by N packed records of
// 32-bit little-endian floats. The written property order is
//   x y z  nx ny nz  f_dc_0..2  f_rest_0..(3K-4)  opacity  scale_0..2  rot_0..3
// with K = (sh_degree + 1)² coefficients per channel and
//   * f_rest channel-major: all R coefficients 1..K-1, then all G, then all B
//     (GaussianSet::colors is coefficient-major [N, K, 3], coefficient 0 = DC);
//   * opacity as the logit, scale_i as log standard deviations, rot as (w, x, y, z)
//     (not normalized; stored as given);
//   * nx ny nz written as 0 and ignored on reading (viewers expect the columns).
//
// Frames and units: training runs in the normalized frame (world_frame.hpp). The
// writer converts back to the original (COLMAP) frame, computing in double and
// rounding once to float:
//   x_orig     = x / norm.scale + norm.center        [original units]
//   scale_orig = log_scale − log(norm.scale)         [log original units]
// Quaternions, SH coefficients and opacity are frame-independent (the normalization
// has no rotation) and are copied bit for bit. With the identity normalization every
// value is copied verbatim, so write→read is lossless. The reader applies no
// transform: it returns the file's own frame.
//
// Ownership: both functions own no state; the returned GaussianSet owns its arrays.
// Errors are reported as PlyError whose message starts with the file path.
#pragma once

#include <filesystem>
#include <stdexcept>

#include "desplat/core/gaussians.hpp"
#include "desplat/core/world_frame.hpp"

namespace desplat {

class PlyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes static Gaussians (SH color mode) as a standard 3DGS PLY in the original frame.
// Atomic: the data goes to "<path>.tmp", is flushed and fsync'ed, then renamed over
// `path`; on failure the temporary is removed and `path` is untouched.
// Throws PlyError for RGB-mode sets (distractors have no SH and no PLY representation),
// inconsistent array sizes, a normalization with a non-positive or non-finite scale,
// values that are (or become, after the frame change) NaN or infinite, and I/O errors.
void write_gaussian_ply(const std::filesystem::path& path, const GaussianSet& gaussians,
                        const WorldNormalization& norm = {});

// Reads a 3DGS PLY into the file's frame as an SH-mode GaussianSet whose sh_degree
// follows from the number of f_rest properties (0, 9, 24, 45 → degree 0..3).
// Accepted: properties in any order, "float" or "float32" types, the optional
// normals nx ny nz (ignored), comment/obj_info lines, and other elements only when
// they are empty (count 0, so no data is skipped).
// Throws PlyError naming the file and the problem for anything else: missing file,
// not a PLY, ascii or big-endian format, no vertex element, a missing, duplicated,
// unknown or non-float property, an f_rest count other than 0/9/24/45, other elements
// that carry data, no end_header within the first 1 MiB, a body shorter or longer than
// N records (checked before allocating), and NaN/Inf values (vertex and property named).
GaussianSet read_gaussian_ply(const std::filesystem::path& path);

}  // namespace desplat
