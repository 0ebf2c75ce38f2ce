// Depth-occlusion masks against analytic ground truth.
#include "artrace/ar/depth_model.h"
#include "artrace/ar/occlusion.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace artrace::ar {
namespace {

constexpr int kW = 64, kH = 48;
constexpr float kNone = std::numeric_limits<float>::infinity();

DepthImage plane(float z) {
  DepthImage d;
  d.width = kW;
  d.height = kH;
  d.depth_m.assign(kW * kH, z);
  return d;
}

ColorImage uniform(uint8_t r, uint8_t g, uint8_t b) {
  ColorImage c;
  c.width = kW;
  c.height = kH;
  c.rgb.resize(kW * kH * 3);
  for (int i = 0; i < kW * kH; ++i) {
    c.rgb[3 * i] = r;
    c.rgb[3 * i + 1] = g;
    c.rgb[3 * i + 2] = b;
  }
  return c;
}

/// A virtual slab over x in [8, 56), y in [8, 40) whose depth runs from 1.5 m to 2.5 m across x.
std::vector<float> slanted_slab() {
  std::vector<float> zv(kW * kH, kNone);
  for (int y = 8; y < 40; ++y) {
    for (int x = 8; x < 56; ++x) zv[y * kW + x] = 1.5f + (x + 0.5f) / 64.0f;
  }
  return zv;
}

void expect_equal_masks(const std::vector<float>& alpha, const std::vector<uint8_t>& truth, const char* what) {
  int wrong = 0;
  for (size_t i = 0; i < alpha.size(); ++i) wrong += (alpha[i] >= 0.5f) != (truth[i] != 0);
  EXPECT_EQ(wrong, 0) << what;
}

TEST(Occlusion, BoxHalfBehindARealPlane) {
  const DepthImage real = plane(2.0f);
  const auto zv = slanted_slab();
  const auto alpha = occlusion_alpha(real, uniform(128, 128, 128), zv);
  const auto truth = exact_visibility(real, zv);
  expect_equal_masks(alpha, truth, "slab through a plane");
  // the boundary is where the slab crosses z = 2: x = 32
  EXPECT_TRUE(truth[20 * kW + 31]);
  EXPECT_FALSE(truth[20 * kW + 32]);
  // soft over a couple of pixels, hard away from the boundary
  EXPECT_GT(alpha[20 * kW + 31], 0.5f);
  EXPECT_LT(alpha[20 * kW + 31], 1.0f);
  EXPECT_EQ(alpha[20 * kW + 20], 1.0f);
  EXPECT_EQ(alpha[20 * kW + 45], 0.0f);
  EXPECT_EQ(alpha[2 * kW + 2], 0.0f) << "no virtual surface there";
}

TEST(Occlusion, SphereInFrontOfAWall) {
  const DepthImage real = plane(3.0f);
  std::vector<float> zv(kW * kH, kNone);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const float r2 = (x - 32.0f) * (x - 32.0f) + (y - 24.0f) * (y - 24.0f);
      if (r2 < 15.0f * 15.0f) zv[y * kW + x] = 1.5f - std::sqrt(15.0f * 15.0f - r2) / 30.0f;
    }
  }
  const auto alpha = occlusion_alpha(real, uniform(90, 90, 90), zv);
  expect_equal_masks(alpha, exact_visibility(real, zv), "sphere before a wall");
  for (size_t i = 0; i < zv.size(); ++i) {
    if (std::isfinite(zv[i])) {
      ASSERT_EQ(alpha[i], 1.0f) << "fully visible, no soft edge against a far wall";
    }
  }
}

/// Holes in a real occluder neither hide nor punch through: small ones are filled, a large region
/// with no reading at all does not hide the virtual surface.
TEST(Occlusion, HolesInTheDepthMap) {
  DepthImage real = plane(1.0f);  // a wall in front of the virtual slab everywhere
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> px(8, 55), py(8, 39);
  for (int k = 0; k < 40; ++k) real.depth_m[py(rng) * kW + px(rng)] = 0.0f;  // speckle
  for (int y = 30; y < 33; ++y)
    for (int x = 12; x < 15; ++x) real.depth_m[y * kW + x] = 0.0f;  // a 3x3 hole
  for (int y = 10; y < 30; ++y)
    for (int x = 30; x < 54; ++x) real.depth_m[y * kW + x] = 0.0f;  // a large region without data
  const auto zv = slanted_slab();
  const auto alpha = occlusion_alpha(real, uniform(100, 100, 100), zv);
  for (int y = 8; y < 40; ++y) {
    for (int x = 8; x < 56; ++x) {
      const bool inside_large = x >= 30 && x < 54 && y >= 10 && y < 30;
      const bool deep_inside = x >= 40 && x < 44 && y >= 18 && y < 22;
      if (!inside_large) {
        ASSERT_LT(alpha[y * kW + x], 0.5f) << "hole punched at " << x << "," << y;
      }
      if (deep_inside) {
        ASSERT_GE(alpha[y * kW + x], 0.5f) << "unknown depth hid the virtual surface at " << x << "," << y;
      }
    }
  }
}

/// Kinect-like noise on the plane: the mask stays within IoU 0.98 of the truth and does not flicker.
TEST(Occlusion, GaussianNoiseNeitherShiftsNorFlickers) {
  const DepthImage exact = plane(2.0f);
  const auto zv = slanted_slab();
  const auto truth = exact_visibility(exact, zv);
  std::vector<std::vector<float>> alphas;
  for (const uint64_t seed : {1u, 2u}) {
    DepthImage noisy = exact;
    std::mt19937 rng(seed);
    std::normal_distribution<float> n(0.0f, 0.0012f + 0.0019f * 1.6f * 1.6f);
    for (float& d : noisy.depth_m) d += n(rng);
    alphas.push_back(occlusion_alpha(noisy, uniform(128, 128, 128), zv));
    const MaskScore s = score_mask(alphas.back(), truth, kW, kH);
    EXPECT_GE(s.iou, 0.98) << "seed " << seed;
    EXPECT_LE(s.boundary_px, 1.0) << "seed " << seed;
  }
  int flips = 0, area = 0;
  for (size_t i = 0; i < zv.size(); ++i) {
    area += std::isfinite(zv[i]);
    flips += (alphas[0][i] >= 0.5f) != (alphas[1][i] >= 0.5f);
  }
  EXPECT_LE(flips, area / 100) << "boundary flicker between two noise realisations";
}

/// The depth map sits one pixel right of the colour image: the colour-guided refinement moves the
/// occlusion boundary back onto the colour edge.
TEST(Occlusion, OnePixelColourDepthOffsetIsCorrected) {
  ColorImage color = uniform(0, 0, 255);
  DepthImage depth = plane(3.0f);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      if (x < 32) {
        color.rgb[3 * (y * kW + x)] = 255;  // a red occluder left of x = 32 in colour ...
        color.rgb[3 * (y * kW + x) + 2] = 0;
      }
      if (x < 33) depth.depth_m[y * kW + x] = 1.0f;  // ... but left of x = 33 in depth
    }
  }
  std::vector<float> zv(kW * kH, 2.0f);  // a virtual wall between the two
  std::vector<uint8_t> truth(kW * kH);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) truth[y * kW + x] = x >= 32;
  OcclusionOptions plain;
  plain.refine = false;
  int wrong_plain = 0;
  const auto a0 = occlusion_alpha(depth, color, zv, plain);
  for (size_t i = 0; i < truth.size(); ++i) wrong_plain += (a0[i] >= 0.5f) != (truth[i] != 0);
  EXPECT_EQ(wrong_plain, kH) << "without refinement one column is wrong";
  expect_equal_masks(occlusion_alpha(depth, color, zv), truth, "refined");
}

}  // namespace
}  // namespace artrace::ar
