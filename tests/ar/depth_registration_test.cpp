// The depth's residual shift from the colour, estimated from a recording: synthetic frames of the
// demo room whose depth is moved by a known shift (by hand here, or by the Kinect-like depth model)
// must give that shift back; colour that does not follow the depth must give none; and the occlusion
// of a virtual box must come out closer to the exact mask once the shift is undone.
#include "artrace/ar/depth_model.h"
#include "artrace/ar/depth_registration.h"
#include "artrace/ar/occlusion.h"
#include "artrace/core/two_level_scene.h"
#include "artrace/io/synth.h"
#include "../cli_util.h"

#include <gtest/gtest.h>

#include <limits>
#include <random>

namespace artrace::ar {
namespace {

constexpr int kW = 320, kH = 240;

std::vector<SensorFrame> room_frames(int frames, std::optional<DepthModel> model) {
  const io::AffScene room = io::load_aff(io::kRoot / "data/scenes/room.aff");
  io::SynthOptions o;
  o.frames = frames;
  o.width = kW;
  o.height = kH;
  o.depth_model = model;
  io::Synthesizer synth(room, o);
  std::vector<SensorFrame> out;
  for (int k = 0; k < frames; ++k) out.push_back(synth.render(k));
  return out;
}

std::vector<const SensorFrame*> views(const std::vector<SensorFrame>& frames) {
  std::vector<const SensorFrame*> v;
  for (const SensorFrame& f : frames) v.push_back(&f);
  return v;
}

/// The depth a sensor `s` pixels off would record: the colour pixel p's depth lands at p + s.
DepthImage recorded_with_shift(const DepthImage& exact, DepthShift s) {
  DepthImage d = exact;
  for (int y = 0; y < d.height; ++y) {
    for (int x = 0; x < d.width; ++x) {
      const int sx = x - s.dx, sy = y - s.dy;
      d.depth_m[static_cast<size_t>(y) * d.width + x] = sx >= 0 && sy >= 0 && sx < d.width && sy < d.height ? exact.at(sx, sy) : 0.0f;
    }
  }
  return d;
}

TEST(DepthRegistration, RecoversTheShiftTheDepthWasRecordedWith) {
  const std::vector<SensorFrame> exact = room_frames(4, std::nullopt);
  for (const DepthShift s : {DepthShift{0, 0}, DepthShift{1, 0}, DepthShift{-2, 1}, DepthShift{0, -2}, DepthShift{2, 2}}) {
    std::vector<SensorFrame> shifted = exact;
    for (SensorFrame& f : shifted) f.depth = recorded_with_shift(f.depth, s);
    const DepthShiftEstimate e = estimate_depth_shift(views(shifted));
    EXPECT_TRUE(e.confident) << s.dx << "," << s.dy << ": " << e.describe();
    EXPECT_EQ(e.shift, s) << e.describe();
    // and undoing it gives the exact depth back wherever the shifted image held it
    const DepthImage back = shift_depth(shifted[1].depth, e.shift);
    int compared = 0, differ = 0;
    for (int y = 2; y < kH - 2; ++y) {
      for (int x = 2; x < kW - 2; ++x) {
        ++compared;
        differ += back.at(x, y) != exact[1].depth.at(x, y);
      }
    }
    EXPECT_EQ(differ, 0) << "of " << compared;
  }
}

TEST(DepthRegistration, FindsTheKinectLikeModelsOffsetThroughItsNoise) {
  for (const int offset : {1, -2}) {
    DepthModel m;
    m.color_offset_px = offset;
    const std::vector<SensorFrame> frames = room_frames(6, m);
    const DepthShiftEstimate e = estimate_depth_shift(views(frames));
    EXPECT_TRUE(e.confident) << e.describe();
    EXPECT_EQ(e.shift, (DepthShift{offset, 0})) << e.describe();
  }
}

TEST(DepthRegistration, NoShiftWithoutAClearPeak) {
  std::vector<SensorFrame> frames = room_frames(3, std::nullopt);
  {
    // colour that does not follow the depth: every shift scores alike
    std::vector<SensorFrame> noise = frames;
    std::mt19937 rng(7);
    for (SensorFrame& f : noise)
      for (uint8_t& c : f.color.rgb) c = static_cast<uint8_t>(rng() & 255);
    const DepthShiftEstimate e = estimate_depth_shift(views(noise));
    EXPECT_FALSE(e.confident) << e.describe();
    EXPECT_TRUE(e.shift.zero());
  }
  {
    // a shift beyond the window: its best candidate is on the window's edge, which does not count
    std::vector<SensorFrame> far = frames;
    for (SensorFrame& f : far) f.depth = recorded_with_shift(f.depth, {5, 0});
    const DepthShiftEstimate e = estimate_depth_shift(views(far));
    EXPECT_EQ(e.best.dx, 3) << e.describe();
    EXPECT_FALSE(e.confident) << e.describe();
    EXPECT_TRUE(e.shift.zero());
    DepthShiftOptions wide;
    wide.max_shift = 6;
    EXPECT_EQ(estimate_depth_shift(views(far), wide).shift, (DepthShift{5, 0}));
  }
  {
    // colour blurred over 9 px: the colour step is spread over the pixels beside every edge, and
    // the scores make a broad hill around the true shift rather than a peak
    std::vector<SensorFrame> blurred = frames;
    for (SensorFrame& f : blurred) {
      f.depth = recorded_with_shift(f.depth, {1, 0});
      const std::vector<uint8_t> src = f.color.rgb;
      for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x)
          for (int c = 0; c < 3; ++c) {
            int sum = 0, n = 0;
            for (int v = std::max(0, y - 4); v <= std::min(kH - 1, y + 4); ++v)
              for (int u = std::max(0, x - 4); u <= std::min(kW - 1, x + 4); ++u) sum += src[3 * (v * kW + u) + c], ++n;
            f.color.rgb[3 * (y * kW + x) + c] = static_cast<uint8_t>(sum / n);
          }
    }
    DepthShiftOptions wide;
    wide.max_shift = 6;
    const DepthShiftEstimate e = estimate_depth_shift(views(blurred), wide);
    EXPECT_FALSE(e.confident) << e.describe();
    EXPECT_TRUE(e.shift.zero());
  }
  {
    // too few discontinuities to tell: one frame's worth, asked for more
    DepthShiftOptions strict;
    strict.min_discontinuities = 1000000;
    EXPECT_FALSE(estimate_depth_shift(views(frames), strict).confident);
  }
}

TEST(DepthRegistration, ShiftDepthAndTheShiftedSource) {
  DepthImage d;
  d.width = 4;
  d.height = 3;
  d.depth_m = {1, 2, 3, 4,  //
               5, 6, 7, 8,  //
               9, 10, 11, 12};
  const DepthImage s = shift_depth(d, {1, -1});  // out(x, y) = in(x + 1, y - 1)
  const std::vector<float> want = {0, 0, 0, 0,  //
                                   2, 3, 4, 0,  //
                                   6, 7, 8, 0};
  EXPECT_EQ(s.depth_m, want);
  EXPECT_EQ(shift_depth(d, {0, 0}).depth_m, d.depth_m);

  SensorFrame f;
  f.depth = d;
  auto inner = std::make_unique<FrameList>(std::vector<SensorFrame>{f, f, f}, "three frames");
  DepthShiftedSource src(std::move(inner), {1, -1});
  EXPECT_EQ(src.frame_count(), 3);
  src.seek(2);
  SensorFrame got;
  ASSERT_TRUE(src.next(got));
  EXPECT_EQ(got.depth.depth_m, want);
  EXPECT_FALSE(src.next(got));
  EXPECT_NE(src.describe().find("depth shifted 1,-1 px"), std::string::npos) << src.describe();
}

TEST(DepthRegistration, UndoingTheShiftBringsTheOcclusionBoundaryToTheTruth) {
  // the box bench-occlusion uses, standing among the room's furniture
  core::TwoLevelScene virt;
  virt.add_instance(virt.add_rigid_mesh(core::box_triangles({-0.45f, 0.0f, -1.3f}, {-0.05f, 1.1f, -0.75f})), glm::mat4(1.0f));
  virt.commit();
  const std::vector<SensorFrame> exact = room_frames(8, std::nullopt), noisy = room_frames(8, DepthModel{});
  const DepthShift s = estimate_depth_shift(views(noisy)).shift;
  ASSERT_EQ(s, (DepthShift{1, 0}));
  double error_as_read = 0.0, error_shifted = 0.0;
  int frames = 0;
  for (size_t k = 0; k < exact.size(); ++k) {
    const core::Camera cam = make_camera(noisy[k].color_intrinsics, *noisy[k].world_from_camera);
    std::vector<float> zv(static_cast<size_t>(kW) * kH, std::numeric_limits<float>::infinity());
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const core::Hit h = virt.intersect(cam.ray(x + 0.5f, y + 0.5f));
        if (h.valid()) zv[static_cast<size_t>(y) * kW + x] = h.t;
      }
    const std::vector<uint8_t> truth = exact_visibility(exact[k].depth, zv), covered = covered_pixels(zv);
    const MaskScore as_read = score_mask(occlusion_alpha(noisy[k].depth, noisy[k].color, zv), truth, covered, kW, kH);
    const MaskScore shifted = score_mask(occlusion_alpha(shift_depth(noisy[k].depth, s), noisy[k].color, zv), truth, covered, kW, kH);
    if (as_read.boundary_pixels == 0 || shifted.boundary_pixels == 0) continue;
    error_as_read += as_read.boundary_px;
    error_shifted += shifted.boundary_px;
    ++frames;
  }
  ASSERT_GE(frames, 4);
  EXPECT_LT(error_shifted, 0.8 * error_as_read) << "mean boundary error " << error_shifted / frames << " px against " << error_as_read / frames;
}

}  // namespace
}  // namespace artrace::ar
