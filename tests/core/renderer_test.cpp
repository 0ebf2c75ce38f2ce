#include "artrace/core/renderer.h"
#include "../test_util.h"

#include <atomic>
#include <stdexcept>
#include <vector>

namespace artrace::core {
namespace {

TEST(Camera, LookAtCentreRayPointsAtTarget) {
  const Camera c = Camera::look_at({1, 2, 3}, {1, 2, -7}, {0, 1, 0}, 90.0f, 100, 50);
  const glm::vec3 d = glm::normalize(c.direction(50.0f, 25.0f));
  EXPECT_NEAR(d.z, -1.0f, 1e-6f);
  // 90 degrees vertical: the top edge of the image looks 45 degrees up
  const glm::vec3 top = glm::normalize(c.direction(50.0f, 0.0f));
  EXPECT_NEAR(top.y, std::sqrt(0.5f), 1e-5f);
  // x grows to the right: +x in the world for a camera looking down -z
  EXPECT_GT(c.direction(100.0f, 25.0f).x, 0.0f);
  EXPECT_THROW(Camera::look_at({0, 0, 0}, {0, 1, 0}, {0, 1, 0}, 60.0f, 10, 10), std::invalid_argument);
}

TEST(Camera, GlPoseMatchesLookAt) {
  const Camera a = Camera::look_at({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 40.0f, 64, 48);
  const Camera b = Camera::from_gl_pose({0, 0, 0}, glm::mat3(1.0f), 40.0f, 64, 48);
  for (const float u : {0.5f, 20.0f, 63.5f}) {
    EXPECT_NEAR(glm::length(a.direction(u, 7.0f) - b.direction(u, 7.0f)), 0.0f, 1e-6f);
  }
}

/// A square of side 2 at distance 4 seen with a 90 degree camera covers exactly the middle half
/// of the image rows and columns; the image is the same with packets or single rays and with any
/// thread count.
TEST(Renderer, SquareCoversAnalyticPixels) {
  const std::vector<Triangle> quad{{{-2, -2, -4}, {2, -2, -4}, {2, 2, -4}}, {{-2, -2, -4}, {2, 2, -4}, {-2, 2, -4}}};
  const KdTree tree(quad);
  const Camera cam = Camera::look_at({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 90.0f, 64, 40);
  // half-width of the view at distance 4 is 4 (vertically): the square spans [-2, 2] -> rows 10..29
  const Image img = render_eye_light(tree, cam, {1, true});
  int covered = 0;
  for (int y = 0; y < 40; ++y) {
    for (int x = 0; x < 64; ++x) {
      const bool lit = img.at(x, y).x > 0.0f;
      const bool inside = x >= 22 && x < 42 && y >= 10 && y < 30;
      ASSERT_EQ(lit, inside) << x << "," << y;
      covered += lit;
    }
  }
  EXPECT_EQ(covered, 20 * 20);
  for (const RenderOptions opt : {RenderOptions{2, true}, RenderOptions{2, false}, RenderOptions{3, false}}) {
    const Image other = render_eye_light(tree, cam, opt);
    EXPECT_EQ(other.pixels, img.pixels);
  }
}

TEST(Renderer, EveryTileVisitedOnce) {
  for (const int size : {kTileSize, 5, 32}) {
    std::vector<int> count(37 * 21, 0);
    std::atomic<int> too_large{0};
    for_each_tile(
        37, 21, 2,
        [&](const Tile& t) {
          too_large += t.x1 - t.x0 > size || t.y1 - t.y0 > size || t.x0 % size != 0 || t.y0 % size != 0;
          for (int y = t.y0; y < t.y1; ++y)
            for (int x = t.x0; x < t.x1; ++x) ++count[y * 37 + x];
        },
        size);
    for (const int c : count) EXPECT_EQ(c, 1) << "tile size " << size;
    EXPECT_EQ(too_large.load(), 0) << "tile size " << size;
  }
  EXPECT_THROW(for_each_tile(8, 8, 1, [](const Tile&) {}, 0), std::invalid_argument);
}

}  // namespace
}  // namespace artrace::core
