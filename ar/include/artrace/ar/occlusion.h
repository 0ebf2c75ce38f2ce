// Depth-aware occlusion of virtual surfaces by the real scene a depth sensor saw.
//
// A per-pixel `z_real < z_virtual` test fails on real depth maps: holes (no reading) punch holes
// into real occluders, noise makes the boundary flicker, and depth edges sit a pixel or two away
// from the colour edges the eye sees. Here:
//   1. small holes are filled from the valid depths around them (a few growing passes); large
//      ones stay unknown, and what is unknown does not hide anything;
//   2. the virtual surface's visibility is soft: alpha = clamp(0.5 + (z_real - z_virtual) / (2 b))
//      with a band b that grows with the sensor's noise, b = k (1.2 mm + 1.9 mm (z - 0.4 m)^2)
//      (Nguyen, Izadi & Lovell, 3DIMPVT 2012), so noise shifts alpha a little instead of toggling it;
//   3. alpha is refined with a joint bilateral filter guided by the colour image (C. Richardt et al.,
//      "Coherent spatiotemporal filtering, upsampling and rendering of RGBZ videos", Eurographics
//      2012, do this for RGBZ), which snaps the boundary to colour edges and blends it over a pixel
//      or two. It pulls back part of a boundary that a depth map offset from the colour puts a
//      pixel off, not all of it: the tools undo a whole-pixel offset first (depth_registration.h).
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <optional>
#include <vector>

namespace artrace::ar {

struct OcclusionOptions {
  int fill_radius = 2;          ///< window radius of the hole filling median
  int fill_passes = 4;          ///< holes up to about radius x passes pixels across are filled
  int max_hole_px = 64;         ///< larger connected holes stay unknown (they hide nothing)
  double band_sigmas = 3.0;     ///< k: band width in multiples of the noise sigma
  double min_band_m = 0.005;    ///< floor of the band
  bool refine = true;           ///< colour-guided refinement of alpha
  int guide_radius = 3;
  double guide_sigma_color = 20.0;  ///< in 8-bit colour units
  double guide_sigma_space = 1.5;   ///< in pixels
  int threads = 0;  ///< workers for the hole filling's passes and the refinement (0: every core); the result is the same for any count
};

/// Fills holes (0) of a depth map from the far side of their valid neighbours; connected holes of
/// more than `max_hole_px` pixels stay 0. Each of the `passes` gives every hole pixel with valid
/// depths in its (2 radius + 1)^2 window the upper quartile of them (the value at index 3/4 of
/// their count, sorted), from the depths the pass began with. On `threads` workers (0: every
/// core); the result is the same for any count.
DepthImage fill_depth_holes(const DepthImage& depth, int radius, int passes, int max_hole_px, int threads = 0);

/// Visibility of the virtual surface at each pixel, 0 (hidden by the real scene) .. 1 (in front).
/// `virtual_depth_m` is the camera-space depth of the virtual surface per pixel (+inf where there
/// is none, and those pixels get alpha 0). `color` guides the refinement; it must be the size of
/// the depth map.
std::vector<float> occlusion_alpha(const DepthImage& sensor_depth, const ColorImage& color,
                                   const std::vector<float>& virtual_depth_m, const OcclusionOptions& options = {});

/// occlusion_alpha for a depth map whose holes fill_depth_holes has already filled (the compositor
/// fills once for the occlusion and the shadows on real surfaces): the soft test and the refinement.
std::vector<float> occlusion_alpha_filled(const DepthImage& filled_depth, const ColorImage& color, const std::vector<float>& virtual_depth_m,
                                          const OcclusionOptions& options = {});

/// The hard ground-truth mask from exact depth: 1 where the virtual surface is in front.
std::vector<uint8_t> exact_visibility(const DepthImage& exact_depth, const std::vector<float>& virtual_depth_m);

/// Agreement of a soft mask (thresholded at 0.5) with a hard one, measured where occlusion can be
/// wrong. `covered` marks the pixels a virtual surface covers (finite virtual depth): a change of
/// the mask between a covered and an uncovered pixel is the object's outline, right by construction,
/// so it is not scored.
///   - occlusion boundary O(m): visible pixels of m with a 4-neighbour that is covered but hidden;
///   - full boundary F(m): visible pixels of m with a 4-neighbour that is not visible;
///   - boundary_px: each pixel of O(truth) is measured to the nearest pixel of F(estimate), each of
///     O(estimate) to F(truth), and the distances averaged over both sets (symmetric: a missed
///     occlusion costs its distance to the boundary the estimate does draw, a false one likewise).
///     Where the other side has no boundary at all the distance is the image diagonal.
struct MaskScore {
  double iou = 1.0;             ///< of the visible sets; 1 when both are empty
  double boundary_px = 0.0;     ///< symmetric mean distance on the occlusion boundary (0 when there is none)
  int boundary_pixels = 0;      ///< |O(truth)| + |O(estimate)|: how many distances boundary_px averages
  int truth_boundary_pixels = 0;  ///< |O(truth)|
  /// The one-sided figure this metric replaces: every boundary pixel of the estimate, the object's
  /// outline included, to the truth's nearest one. Kept to compare with earlier reports.
  double outline_boundary_px = 0.0;
  int false_visible = 0, false_hidden = 0;
};
MaskScore score_mask(const std::vector<float>& alpha, const std::vector<uint8_t>& truth, const std::vector<uint8_t>& covered,
                     int width, int height);

/// Flicker of the estimate between two frames that the truth does not explain: covered pixels (in
/// both frames) where the estimate changed and the truth did not, or the reverse, per pixel of the
/// current truth's occlusion boundary. Empty when the truth has no occlusion boundary.
std::optional<double> occlusion_jitter(const std::vector<float>& previous_alpha, const std::vector<float>& alpha,
                                       const std::vector<uint8_t>& previous_truth, const std::vector<uint8_t>& truth,
                                       const std::vector<uint8_t>& previous_covered, const std::vector<uint8_t>& covered,
                                       int width, int height);

/// 1 where the virtual depth is finite.
std::vector<uint8_t> covered_pixels(const std::vector<float>& virtual_depth_m);

}  // namespace artrace::ar
