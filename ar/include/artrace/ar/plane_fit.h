// Planes of the real scene from depth maps: a robust fit around one pixel (to stand a virtual
// object on the surface seen there) and the large planes of a frame (to choose one). RANSAC
// (M. A. Fischler and R. C. Bolles, "Random Sample Consensus", CACM 24(6), 1981) with an inlier
// band that follows the sensor's noise at the surface's distance (Nguyen, Izadi & Lovell,
// 3DIMPVT 2012: sigma = 1.2 mm + 1.9 mm (z - 0.4 m)^2), then a least-squares refit on the inliers.
// Deterministic: the samples come from a fixed seed.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <Eigen/Core>

#include <optional>
#include <vector>

namespace artrace::ar {

struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, towards the camera that saw it (world)
  Eigen::Vector3d point = Eigen::Vector3d::Zero();    ///< on the plane (world)
  int inliers = 0;
  double rms_m = 0.0;       ///< of the inliers' distances
  double area_m2 = 0.0;     ///< the inliers' footprint on the plane (frames only)
  int pixel_u = 0, pixel_v = 0;  ///< a pixel that sees the plane (frames only)
  double distance(const Eigen::Vector3d& p) const { return normal.dot(p - point); }
};

struct RansacOptions {
  double threshold_m = 0.01;  ///< inlier band (half width)
  int iterations = 300;
  uint64_t seed = 1;
  double min_fraction = 1.0 / 3.0;  ///< of the points the plane must hold
  int min_inliers = 3;
  /// A point the plane must pass within the band (the surface seen at a pixel, where a window of
  /// depths also holds another surface); none: any plane.
  std::optional<Eigen::Vector3d> through;
};

/// The plane with the most points within the band (and through `through`, when given), refitted on
/// them and then on a band narrowed to 2.5 robust sigmas of the inliers' residuals (1.4826 x their
/// median absolute deviation), until it settles: a band as wide as the noise model's 3 sigma at a distance
/// also holds a step a few centimetres high (a table top's edge), which the narrowed band leaves
/// out. Empty with fewer than 3 points or when the best plane holds fewer than min_fraction of them
/// or min_inliers.
std::optional<Plane> fit_plane(const std::vector<Eigen::Vector3d>& points, const RansacOptions& options = {});

/// The sensor's depth noise (one sigma, metres) at depth z.
double kinect_sigma_m(double z);

/// The plane seen around pixel (u, v) of a frame, from the valid depths within `radius_px` (0: the
/// pixels within 25 cm of the point seen there, 8 to 64 of them, sampled to about 25 x 25; where no
/// plane holds half of those, half and a quarter of that radius, down to 8 pixels), in the frame's
/// world coordinates (camera coordinates without a pose), through the surface seen at the pixel
/// itself. Its `point` is where the pixel's ray meets the plane. Empty where too few depths or no
/// plane holds half of them.
std::optional<Plane> plane_at_pixel(const SensorFrame& frame, int u, int v, int radius_px = 0);

struct PlaneDetection {
  int stride = 4;             ///< every stride-th pixel in each direction
  int max_planes = 8;
  double min_area_m2 = 0.05;  ///< smaller planes are not reported
  double max_depth_m = 6.0;
};

/// The large planes of a frame, largest first (sequential RANSAC on the sampled depth points).
std::vector<Plane> detect_planes(const SensorFrame& frame, const PlaneDetection& options = {});

}  // namespace artrace::ar
