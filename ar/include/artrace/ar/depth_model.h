// A Kinect-like depth sensor model applied to exact depth, so tests and benchmarks know the truth
// and see what real depth maps look like. After K. Khoshelham and S. Oude Elberink, "Accuracy and
// Resolution of Kinect Depth Data", Sensors 12(2), 2012 (noise and quantisation growing with z^2),
// and C. Nguyen, S. Izadi and D. Lovell, "Modeling Kinect Sensor Noise", 3DIMPVT 2012 (axial noise
// 1.2 mm + 1.9 mm (z - 0.4)^2; missing depth at grazing angles).
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <cstdint>

namespace artrace::ar {

struct DepthModel {
  double disparity_step = 1.0 / 8.0;  ///< disparity quantisation in pixels
  double baseline_focal = 0.075 * 580.0;  ///< baseline (m) times focal length (px): z = bf / d
  bool noise = true;                  ///< axial Gaussian noise (Nguyen et al.)
  double grazing_cos = 0.15;          ///< no reading where the surface is seen this obliquely
  double edge_jump = 0.05;            ///< relative depth jump that counts as a silhouette
  double edge_drop = 0.5;             ///< probability that a silhouette pixel has no reading
  int color_offset_px = 1;            ///< depth shifted this many pixels right of colour
  double max_range_m = 8.0;
  double min_range_m = 0.4;
};

/// Applies the model to `depth` in place (deterministic for a given seed).
void apply_depth_model(DepthImage& depth, const PinholeIntrinsics& k, const DepthModel& model, uint64_t seed);

}  // namespace artrace::ar
