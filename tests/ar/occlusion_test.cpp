// Depth-occlusion masks against analytic ground truth.
#include "artrace/ar/depth_model.h"
#include "artrace/ar/occlusion.h"

#include <gtest/gtest.h>

#include <algorithm>
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
  const int g = OcclusionOptions{}.guide_radius;  // the colour-guided refinement blends over this many pixels
  ASSERT_LT(g, 4);
  for (int y = 8; y < 40; ++y) {
    for (int x = 8; x < 56; ++x) {
      const bool near_large = x >= 30 - g && x < 54 + g && y >= 10 - g && y < 30 + g;
      // hole filling reaches fill_radius x fill_passes = 8 pixels into a hole it may fill; this
      // one is too large to fill at all, so everything but the refinement's blend at its rim
      // shows the virtual surface
      const bool deep_inside = x >= 34 && x < 50 && y >= 14 && y < 26;
      if (!near_large) {
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
    const MaskScore s = score_mask(alphas.back(), truth, covered_pixels(zv), kW, kH);
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


/// The colour-guided refinement against its definition, worked out pixel by pixel: a virtual pixel
/// whose 7x7 window holds an alpha more than 0.01 off its own takes the mean of the window's
/// virtual pixels' alphas, weighted by colour likeness and distance; every other keeps its alpha.
/// Random depth steps, colours, holes and virtual coverage, the window clipped at the borders.
TEST(Occlusion, RefinementMatchesItsDefinitionPixelByPixel) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int round = 0; round < 5; ++round) {
    DepthImage depth = plane(2.0f);
    ColorImage color = uniform(0, 0, 0);
    std::vector<float> zv(kW * kH, kNone);
    for (int i = 0; i < kW * kH && round == 4; ++i) {
      // the last round: a real step at x = 30 in front of a virtual wall, one colour: alphas of 0
      // and 1 in straight columns, so a window's edge column alone can differ from the rest
      depth.depth_m[i] = i % kW < 30 ? 1.0f : 3.0f;
      zv[i] = 2.0f;
    }
    for (int i = 0; i < kW * kH && round < 4; ++i) {
      const int x = i % kW, y = i / kW;
      depth.depth_m[i] = (x + 3 * y + 11 * round) % 37 < 15 ? 1.0f + 0.01f * u(rng) : 2.5f + 0.01f * u(rng);
      if (u(rng) < 0.03f) depth.depth_m[i] = 0.0f;
      for (int c = 0; c < 3; ++c) color.rgb[3 * i + c] = static_cast<uint8_t>(u(rng) < 0.5f ? 40 + 20 * u(rng) : 200 + 20 * u(rng));
      if (u(rng) < 0.9f && x > 2 + round) zv[i] = 1.2f + 1.6f * u(rng) * (x < kW / 2 ? 1.0f : 0.5f);
      // in the lower half, virtual surfaces within the soft band of the real one: alphas between 0
      // and 1 that differ from their neighbours' by every amount, around the 0.01 that counts
      if (y >= kH / 2 && depth.depth_m[i] > 0.0f && std::isfinite(zv[i])) zv[i] = depth.depth_m[i] + 0.001f * (u(rng) - 0.5f);
    }
    OcclusionOptions plain;
    plain.refine = false;
    const OcclusionOptions o;
    const std::vector<float> a = occlusion_alpha_filled(depth, color, zv, plain);
    const std::vector<float> refined = occlusion_alpha_filled(depth, color, zv, o);
    const int r = o.guide_radius;
    int mixed = 0;
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) {
        const int i = y * kW + x;
        bool off = false;
        double sum = 0.0, wsum = 0.0;
        for (int yy = std::max(0, y - r); yy <= std::min(kH - 1, y + r); ++yy) {
          for (int xx = std::max(0, x - r); xx <= std::min(kW - 1, x + r); ++xx) {
            const int j = yy * kW + xx;
            off = off || std::fabs(a[j] - a[i]) > 0.01f;
            if (!std::isfinite(zv[j])) continue;
            double dc = 0.0;
            for (int c = 0; c < 3; ++c) dc += std::pow(color.rgb[3 * i + c] - color.rgb[3 * j + c], 2);
            const double wt = std::exp(-dc / (2.0 * o.guide_sigma_color * o.guide_sigma_color) -
                                       ((xx - x) * (xx - x) + (yy - y) * (yy - y)) / (2.0 * o.guide_sigma_space * o.guide_sigma_space));
            sum += wt * a[j];
            wsum += wt;
          }
        }
        const bool refine = std::isfinite(zv[i]) && off && wsum > 0.0;
        mixed += refine;
        ASSERT_NEAR(refined[i], refine ? sum / wsum : a[i], 1e-5) << "round " << round << " pixel " << x << "," << y;
      }
    }
    if (round == 4) {
      EXPECT_EQ(mixed, 6 * kH) << "the three columns either side of the step, in every row";
    } else {
      EXPECT_GT(mixed, kW * kH / 10) << "round " << round;
      EXPECT_LT(mixed, kW * kH * 9 / 10) << "round " << round;
    }
  }
}

/// Masks for the metric tests: a virtual surface covering columns [8, 56) of every row.
std::vector<uint8_t> columns(int x0, int x1) {
  std::vector<uint8_t> m(kW * kH, 0);
  for (int y = 0; y < kH; ++y)
    for (int x = x0; x < x1; ++x) m[y * kW + x] = 1;
  return m;
}

std::vector<float> as_alpha(const std::vector<uint8_t>& m) { return std::vector<float>(m.begin(), m.end()); }

TEST(OcclusionMetric, ShiftedEdgeCostsItsShiftBothWays) {
  const auto covered = columns(8, 56);
  const auto truth = columns(8, 32);  // real geometry hides x >= 32
  const MaskScore s = score_mask(as_alpha(columns(8, 30)), truth, covered, kW, kH);
  // O(truth) is column 31, O(estimate) column 29; each is 2 pixels from the other's boundary
  EXPECT_EQ(s.truth_boundary_pixels, kH);
  EXPECT_EQ(s.boundary_pixels, 2 * kH);
  EXPECT_DOUBLE_EQ(s.boundary_px, 2.0);
  EXPECT_DOUBLE_EQ(s.iou, 22.0 / 24.0);
  EXPECT_EQ(s.false_hidden, 2 * kH);
  EXPECT_EQ(s.false_visible, 0);
}

TEST(OcclusionMetric, ObjectOutlineIsNotScored) {
  const auto covered = columns(8, 56);
  const auto truth = columns(8, 32);
  const MaskScore s = score_mask(as_alpha(truth), truth, covered, kW, kH);
  EXPECT_DOUBLE_EQ(s.boundary_px, 0.0);
  EXPECT_EQ(s.boundary_pixels, 2 * kH) << "both sides' occlusion boundary: column 31";
  EXPECT_DOUBLE_EQ(s.iou, 1.0);
  // no occlusion at all: only an outline, nothing to measure
  const MaskScore none = score_mask(as_alpha(covered), covered, covered, kW, kH);
  EXPECT_EQ(none.boundary_pixels, 0);
  EXPECT_DOUBLE_EQ(none.boundary_px, 0.0);
}

TEST(OcclusionMetric, MissedEdgeCostsTheDistanceToTheBoundaryDrawn) {
  const auto covered = columns(8, 56);
  const auto truth = columns(8, 32);
  // the estimate shows the whole object: its only boundary is the outline, columns 8 and 55;
  // column 31 is 23 pixels from column 8 (24 from column 55); the estimate has no occlusion boundary
  const MaskScore s = score_mask(as_alpha(covered), truth, covered, kW, kH);
  EXPECT_EQ(s.boundary_pixels, kH);
  EXPECT_DOUBLE_EQ(s.boundary_px, 23.0);
  // the earlier figure marks pixels whose left or upper neighbour differs, estimate to truth only:
  // the estimate's columns 8 and 56 against the truth's 8 and 32, (0 + 24) / 2
  EXPECT_DOUBLE_EQ(s.outline_boundary_px, 12.0);
}

TEST(OcclusionMetric, EmptyMasks) {
  const std::vector<uint8_t> nothing(kW * kH, 0);
  const MaskScore s = score_mask(as_alpha(nothing), nothing, nothing, kW, kH);
  EXPECT_DOUBLE_EQ(s.iou, 1.0);
  EXPECT_EQ(s.boundary_pixels, 0);
  EXPECT_DOUBLE_EQ(s.boundary_px, 0.0);
  // an estimate that shows nothing of a partly hidden object: IoU 0, and each truth boundary pixel
  // costs the image diagonal (there is no boundary to measure to): hypot(64, 48) = 80
  const auto covered = columns(8, 56);
  const MaskScore miss = score_mask(as_alpha(nothing), columns(8, 32), covered, kW, kH);
  EXPECT_DOUBLE_EQ(miss.iou, 0.0);
  EXPECT_DOUBLE_EQ(miss.boundary_px, 80.0);
}

TEST(OcclusionMetric, JitterIsPerPixelOfTrueOcclusionBoundary) {
  const auto covered = columns(8, 56);
  const auto truth = columns(8, 32);
  // the estimate gains column 32 in the second frame while the truth stays: 48 unexplained
  // changes over 48 boundary pixels
  const auto j = occlusion_jitter(as_alpha(truth), as_alpha(columns(8, 33)), truth, truth, covered, covered, kW, kH);
  ASSERT_TRUE(j.has_value());
  EXPECT_DOUBLE_EQ(*j, 1.0);
  // the truth moves by a column and the estimate follows: nothing unexplained
  const auto follow = occlusion_jitter(as_alpha(truth), as_alpha(columns(8, 33)), truth, columns(8, 33), covered, covered, kW, kH);
  EXPECT_DOUBLE_EQ(*follow, 0.0);
  // changes at the outline (the object moves) are not jitter
  const auto moved = occlusion_jitter(as_alpha(columns(8, 32)), as_alpha(columns(10, 32)), columns(8, 32), columns(10, 32),
                                      covered, columns(10, 56), kW, kH);
  EXPECT_DOUBLE_EQ(*moved, 0.0);
  // no occlusion boundary in the truth: nothing to divide by
  EXPECT_FALSE(occlusion_jitter(as_alpha(covered), as_alpha(covered), covered, covered, covered, covered, kW, kH).has_value());
}

/// The soft band follows the sensor's noise, which grows with distance squared (Nguyen et al.):
/// sigma(z) = 1.2 mm + 1.9 mm (z - 0.4)^2, band = 3 sigma. A virtual surface 1 cm in front of a real
/// plane is opaque at 1 m (band 5.65 mm) and only a little more visible than hidden at 4 m.
TEST(Occlusion, SoftBandWidensWithDistance) {
  OcclusionOptions o;
  o.refine = false;
  for (const double z : {1.0, 2.5, 4.0}) {
    const DepthImage real = plane(static_cast<float>(z));
    std::vector<float> zv(kW * kH, static_cast<float>(z - 0.01));
    const auto alpha = occlusion_alpha(real, uniform(128, 128, 128), zv, o);
    const double sigma = 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4);
    const double band = std::max(0.005, 3.0 * sigma);
    const double expected = std::clamp(0.5 + 0.01 / (2.0 * band), 0.0, 1.0);
    EXPECT_NEAR(alpha[20 * kW + 20], expected, 2e-4) << "z = " << z;
  }
  // by hand at 4 m: sigma = 1.2 + 1.9 x 12.96 = 25.824 mm, band 77.47 mm, alpha = 0.5 + 10 / 154.94
  const DepthImage far = plane(4.0f);
  const auto a = occlusion_alpha(far, uniform(128, 128, 128), std::vector<float>(kW * kH, 3.99f), o);
  EXPECT_NEAR(a[20 * kW + 20], 0.5645, 5e-4);
}

/// Holes at a silhouette are the sensor's shadow on the background: they are filled from the far
/// side. A near occluder (1 m) left of x = 32, a far wall (3 m) right of x = 33, no reading at
/// x = 32 and 33 in rows 10-29 (40 pixels: a small hole, which is filled): a virtual surface at 2 m
/// shows through both hole columns. (The pixel at x = 32 has 10 near and 5 far readings in its 5x5
/// window: a median would fill it near, and hide the virtual surface.)
TEST(Occlusion, HolesAtASilhouetteAreFilledFromTheFarSide) {
  DepthImage real = plane(3.0f);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < 32; ++x) real.depth_m[y * kW + x] = 1.0f;
  }
  for (int y = 10; y < 30; ++y) real.depth_m[y * kW + 32] = real.depth_m[y * kW + 33] = 0.0f;
  OcclusionOptions o;
  o.refine = false;
  ASSERT_LT(40, o.max_hole_px) << "the hole must be one that is filled";
  const auto alpha = occlusion_alpha(real, uniform(128, 128, 128), std::vector<float>(kW * kH, 2.0f), o);
  for (int y = 12; y < 28; ++y) {
    EXPECT_EQ(alpha[y * kW + 31], 0.0f) << "the occluder at row " << y;
    EXPECT_EQ(alpha[y * kW + 32], 1.0f) << "the hole next to the occluder, row " << y;
    EXPECT_EQ(alpha[y * kW + 33], 1.0f) << "the hole next to the wall, row " << y;
  }
}

/// fill_depth_holes by its definition, written plainly: each hole (4-connected pixels without a
/// reading) found by a flood fill and kept when it has at most `max_hole` pixels; each pass
/// copies the whole map and gives every kept pixel still empty the value at index 3/4 of the
/// sorted valid depths in its window.
DepthImage fill_by_definition(const DepthImage& d, int radius, int passes, int max_hole) {
  const int w = d.width, h = d.height;
  std::vector<int> label(d.depth_m.size(), -1);
  std::vector<int> size;
  for (int start = 0; start < w * h; ++start) {
    if (d.depth_m[start] > 0.0f || label[start] >= 0) continue;
    const int id = static_cast<int>(size.size());
    size.push_back(0);
    std::vector<int> stack{start};
    label[start] = id;
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      ++size[id];
      const int x = i % w, y = i / w;
      for (const auto& [nx, ny] : {std::pair{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}}) {
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
        const int j = ny * w + nx;
        if (d.depth_m[j] > 0.0f || label[j] >= 0) continue;
        label[j] = id;
        stack.push_back(j);
      }
    }
  }
  DepthImage cur = d;
  for (int pass = 0; pass < passes; ++pass) {
    DepthImage next = cur;
    for (int i = 0; i < w * h; ++i) {
      if (cur.depth_m[i] > 0.0f || size[label[i]] > max_hole) continue;
      std::vector<float> v;
      for (int y = i / w - radius; y <= i / w + radius; ++y) {
        for (int x = i % w - radius; x <= i % w + radius; ++x) {
          if (x >= 0 && y >= 0 && x < w && y < h && cur.depth_m[y * w + x] > 0.0f) v.push_back(cur.depth_m[y * w + x]);
        }
      }
      std::sort(v.begin(), v.end());
      if (!v.empty()) next.depth_m[i] = v[v.size() * 3 / 4];
    }
    cur = next;
  }
  return cur;
}

TEST(Occlusion, HoleFillingMatchesItsDefinitionForAnyThreadCount) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  constexpr int w = 160, h = 120;
  int filled_somewhere = 0, left_somewhere = 0;
  for (int round = 0; round < 6; ++round) {
    DepthImage d;
    d.width = w;
    d.height = h;
    d.depth_m.resize(w * h);
    for (int i = 0; i < w * h; ++i) d.depth_m[i] = 0.5f + 3.0f * u(rng);
    // holes of every size and shape: speckle, random rectangles (which merge into larger, ragged
    // holes), a few touching the border, and readings that are not depths (negative, NaN)
    for (int k = 0; k < 300; ++k) d.depth_m[static_cast<int>(u(rng) * (w * h - 1))] = 0.0f;
    for (int k = 0; k < 25 + 10 * round; ++k) {
      const int x0 = static_cast<int>(u(rng) * w), y0 = static_cast<int>(u(rng) * h);
      const int rw = 1 + static_cast<int>(u(rng) * (round < 3 ? 6 : 20)), rh = 1 + static_cast<int>(u(rng) * 8);
      for (int y = y0; y < std::min(h, y0 + rh); ++y)
        for (int x = x0; x < std::min(w, x0 + rw); ++x) d.depth_m[y * w + x] = 0.0f;
    }
    d.depth_m[5 * w + 7] = -1.0f;
    d.depth_m[9 * w + 100] = std::numeric_limits<float>::quiet_NaN();
    const int radius = 1 + round % 3, passes = 2 + round % 4, max_hole = round == 5 ? 1000000 : 16 + 24 * round;
    const DepthImage want = fill_by_definition(d, radius, passes, max_hole);
    for (const int threads : {1, 2, 3}) {
      const DepthImage got = fill_depth_holes(d, radius, passes, max_hole, threads);
      ASSERT_EQ(got.depth_m.size(), want.depth_m.size());
      for (int i = 0; i < w * h; ++i) {
        // bit for bit (both NaN where the input's NaN stays)
        ASSERT_TRUE(got.depth_m[i] == want.depth_m[i] || (std::isnan(got.depth_m[i]) && std::isnan(want.depth_m[i])))
            << "round " << round << ", " << threads << " threads, pixel " << i % w << "," << i / w << ": " << got.depth_m[i]
            << " against " << want.depth_m[i];
      }
    }
    for (int i = 0; i < w * h; ++i) {
      filled_somewhere += !(d.depth_m[i] > 0.0f) && want.depth_m[i] > 0.0f;
      left_somewhere += !(want.depth_m[i] > 0.0f);
    }
  }
  for (const auto& [ew, eh] : {std::pair{0, 5}, {5, 0}, {0, 0}}) {
    DepthImage empty;
    empty.width = ew;
    empty.height = eh;
    EXPECT_TRUE(fill_depth_holes(empty, 2, 4, 64).depth_m.empty()) << ew << "x" << eh;
  }
  EXPECT_GT(filled_somewhere, 1000) << "holes filled";
  EXPECT_GT(left_somewhere, 1000) << "holes left: too large, or out of reach of the passes";
}

}  // namespace
}  // namespace artrace::ar
