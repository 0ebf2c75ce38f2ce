#include "artrace/ar/pinhole_intrinsics.h"

#include <gtest/gtest.h>

namespace artrace::ar {
namespace {

TEST(PinholeIntrinsics, ProjectUnprojectRoundTrip) {
  const PinholeIntrinsics k{640, 480, 525.0, 525.0, 319.5, 239.5};
  const Eigen::Vector3d p = k.unproject(100.0, 50.0, 2.0);
  const Eigen::Vector2d uv = k.project(p);
  EXPECT_NEAR(uv.x(), 100.0, 1e-9);
  EXPECT_NEAR(uv.y(), 50.0, 1e-9);
}

TEST(PinholeIntrinsics, CameraRaysPassThroughUnprojectedPoints) {
  const PinholeIntrinsics k{640, 480, 525.0, 520.0, 319.5, 239.5};
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.rotate(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1.0, -0.1).normalized()));
  pose.pretranslate(Eigen::Vector3d(1.0, -2.0, 0.5));
  const core::Camera cam = make_camera(k, pose);
  const Eigen::Vector3d world = pose * k.unproject(100.0, 50.0, 3.0);
  const glm::vec3 d = cam.direction(100.5f, 50.5f);  // centre of pixel (100, 50); camera-space z = 1: t = depth
  const glm::vec3 p = cam.position + 3.0f * d;
  EXPECT_NEAR(p.x, world.x(), 1e-5);
  EXPECT_NEAR(p.y, world.y(), 1e-5);
  EXPECT_NEAR(p.z, world.z(), 1e-5);
  EXPECT_THROW(make_camera(PinholeIntrinsics{0, 480, 1, 1, 0, 0}, pose), std::invalid_argument);
}

}  // namespace
}  // namespace artrace::ar
