#include "artrace/ar/plane_fit.h"

#include <gtest/gtest.h>

namespace artrace::ar {
namespace {

/// A 640x480 frame (fx = fy = 525, no pose: camera coordinates) seeing a wall at depth `far`
/// everywhere but a vertical strip of columns [u0, u1) at depth `near`.
SensorFrame strip_frame(int u0, int u1, float near, float far) {
  SensorFrame f;
  f.color_intrinsics = {640, 480, 525.0, 525.0, 319.5, 239.5};
  f.depth_intrinsics = f.color_intrinsics;
  f.depth.width = 640;
  f.depth.height = 480;
  f.depth.depth_m.resize(640 * 480);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) f.depth.depth_m[static_cast<size_t>(y) * 640 + x] = x >= u0 && x < u1 ? near : far;
  return f;
}

/// A surface 30 pixels wide (a shelf's edge, a narrow desk between objects) crowded by another in
/// the 25 cm window: the plane at a pixel on it comes from a smaller window, and is its own (the
/// near plane z = 1, facing the camera), not the wall behind.
TEST(PlaneFit, NarrowSurfaceFoundWhereTheWideWindowIsCrowded) {
  const SensorFrame f = strip_frame(280, 310, 1.0f, 3.0f);
  const std::optional<Plane> p = plane_at_pixel(f, 295, 240);
  ASSERT_TRUE(p.has_value()) << "no plane on the strip";
  EXPECT_NEAR(p->normal.z(), -1.0, 1e-6) << "facing the camera";
  EXPECT_NEAR(p->point.z(), 1.0, 1e-6);
  EXPECT_EQ(p->pixel_u, 295);
  // with the window forced to 64 pixels the strip holds too few depths: no plane
  EXPECT_FALSE(plane_at_pixel(f, 295, 240, 64).has_value());
  // the wall beside it is found as the wall
  const std::optional<Plane> wall = plane_at_pixel(f, 100, 240);
  ASSERT_TRUE(wall.has_value());
  EXPECT_NEAR(wall->point.z(), 3.0, 1e-6);
}

/// A pixel with no surface around it (no readings) has no plane.
TEST(PlaneFit, NoPlaneWithoutDepth) {
  SensorFrame f = strip_frame(0, 0, 1.0f, 0.0f);
  EXPECT_FALSE(plane_at_pixel(f, 320, 240).has_value());
}

}  // namespace
}  // namespace artrace::ar
