#include "artrace/io/odometry.h"
#include "artrace/io/oni_reader.h"
#include "artrace/io/recording.h"
#include "artrace/io/recording_writer.h"
#include "artrace/io/synth.h"
#include "artrace/io/tum_reader.h"
#include "../test_util.h"

#include <fstream>

namespace artrace::io {
namespace {

/// A wall (z = -5 plane) seen head-on by a camera at the origin looking down -z.
AffScene wall_scene() {
  const auto dir = ::artrace::test::scratch_path("artrace_synth_wall");
  std::filesystem::create_directories(dir);
  const auto p = dir / "wall.aff";
  std::ofstream(p) << "v\nfrom 0 0 0\nat 0 0 -1\nup 0 1 0\nangle 45\nhither 0.01\nresolution 64 48\n"
                      "l 0 0 0\nf 0.8 0.6 0.4 1 0 0 0 1\np 4\n-50 -50 -5\n50 -50 -5\n50 50 -5\n-50 50 -5\n";
  return load_aff(p);
}

SynthOptions small(int frames) {
  SynthOptions o;
  o.frames = frames;
  o.width = 64;
  o.height = 48;
  o.orbit_deg = 0.0;
  o.threads = 2;
  return o;
}

TEST(Synth, ExactDepthAndPoseOfAWall) {
  const AffScene scene = wall_scene();
  Synthesizer synth(scene, small(2));
  const ar::SensorFrame f = synth.render(0);
  for (const float d : f.depth.depth_m) ASSERT_NEAR(d, 5.0f, 1e-5f) << "depth along the optical axis";
  ASSERT_TRUE(f.world_from_camera.has_value());
  EXPECT_NEAR(f.world_from_camera->translation().norm(), 0.0, 1e-9);
  // the camera's optical axis (z) points down world -z
  EXPECT_NEAR((f.world_from_camera->rotation() * Eigen::Vector3d::UnitZ()).z(), -1.0, 1e-6);
  // 45 degrees over 48 rows: fy = 24 / tan(22.5 deg)
  EXPECT_NEAR(f.color_intrinsics.fy, 24.0 / std::tan(22.5 * M_PI / 180.0), 1e-3);
  EXPECT_GT(f.color.at(32, 24)[0], f.color.at(32, 24)[2]) << "the wall's orange-ish colour";
}

TEST(Synth, KinectModelAddsBoundedNoiseAndHoles) {
  const AffScene scene = wall_scene();
  SynthOptions o = small(1);
  o.depth_model = ar::DepthModel{};
  Synthesizer synth(scene, o);
  const ar::SensorFrame f = synth.render(0);
  int holes = 0, off = 0;
  for (int y = 1; y < 47; ++y) {
    for (int x = 2; x < 63; ++x) {
      const float d = f.depth.at(x, y);
      if (d == 0.0f) ++holes;
      else if (std::fabs(d - 5.0f) > 0.2f) ++off;  // sigma at 5 m is ~4 cm, quantisation ~7 cm
    }
  }
  EXPECT_EQ(off, 0);
  EXPECT_LT(holes, 10) << "a flat wall seen head-on has no silhouettes or grazing angles";
  EXPECT_EQ(f.depth.at(0, 10), 0.0f) << "the colour/depth offset leaves the first column empty";
  int distinct = 0;
  for (int x = 3; x < 60; ++x) distinct += f.depth.at(x, 20) != f.depth.at(x - 1, 20);
  EXPECT_GT(distinct, 0) << "noise makes neighbouring readings differ";
}

/// synth -> ONI -> TUM -> ONI: the two ONI recordings hold the same frames bit for bit, and the
/// TUM copy matches to its quantisation.
TEST(Synth, ConversionsRoundTrip) {
  const AffScene scene = wall_scene();
  SynthOptions o = small(4);
  o.orbit_deg = 20.0;
  const auto tmp = ::artrace::test::scratch_root();
  const auto a = tmp / "artrace_rt_a.oni", t = tmp / "artrace_rt_tum", b = tmp / "artrace_rt_b.oni";
  {
    Synthesizer synth(scene, o);
    auto w = make_recording_writer(a);
    synth.write(*w);
  }
  auto copy = [](const std::filesystem::path& from, const std::filesystem::path& to) {
    auto in = open_recording(from);
    auto out = make_recording_writer(to);
    ar::SensorFrame f;
    while (in->next(f)) out->write(f);
    out->close();
  };
  copy(a, t);
  copy(t, b);
  std::vector<ar::SensorFrame> fa, fb, ft;
  for (auto [path, frames] : {std::pair{a, &fa}, std::pair{b, &fb}, std::pair{t, &ft}}) {
    auto in = open_recording(path);
    ar::SensorFrame f;
    while (in->next(f)) frames->push_back(f);
  }
  ASSERT_EQ(fa.size(), 4u);
  ASSERT_EQ(fb.size(), 4u);
  ASSERT_EQ(ft.size(), 4u);
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(fa[k].depth.depth_m, fb[k].depth.depth_m);
    EXPECT_EQ(fa[k].color.rgb, fb[k].color.rgb);
    EXPECT_EQ(fa[k].color.rgb, ft[k].color.rgb);
    EXPECT_DOUBLE_EQ(fa[k].color_time_s, fb[k].color_time_s);
    for (size_t i = 0; i < fa[k].depth.depth_m.size(); ++i) ASSERT_NEAR(fa[k].depth.depth_m[i], ft[k].depth.depth_m[i], 1e-6f);
    ASSERT_TRUE(fb[k].world_from_camera && ft[k].world_from_camera);
    EXPECT_TRUE(fa[k].world_from_camera->isApprox(*fb[k].world_from_camera, 1e-6));
  }
  EXPECT_FALSE(fa[0].world_from_camera->isApprox(*fa[3].world_from_camera, 1e-3)) << "the camera orbits";
  std::filesystem::remove(a);
  std::filesystem::remove(b);
  std::filesystem::remove(a.string() + ".trajectory.txt");
  std::filesystem::remove(b.string() + ".trajectory.txt");
  std::filesystem::remove_all(t);
}

}  // namespace
}  // namespace artrace::io

namespace artrace::io {
namespace {

/// Frames held in memory, for tests.
class MemorySource : public ar::FrameSource {
 public:
  explicit MemorySource(std::vector<ar::SensorFrame> f) : frames_(std::move(f)) {}
  std::optional<int64_t> frame_count() const override { return static_cast<int64_t>(frames_.size()); }
  bool next(ar::SensorFrame& f) override {
    if (cursor_ >= frames_.size()) return false;
    f = frames_[cursor_++];
    return true;
  }
  void seek(int64_t i) override { cursor_ = static_cast<size_t>(i); }
  std::string describe() const override { return "memory"; }
  double depth_units_per_metre() const override { return 1000.0; }
  std::string intrinsics_source() const override { return "given"; }

 private:
  std::vector<ar::SensorFrame> frames_;
  size_t cursor_ = 0;
};

/// Odometry on a synthetic recording with exact depth follows the exact poses closely.
TEST(Odometry, DriftOnSyntheticRecordingIsSmall) {
  const std::filesystem::path room = std::filesystem::path(ARTRACE_SOURCE_DIR) / "data/scenes/room.aff";
  const AffScene scene = load_aff(room);
  SynthOptions o;
  o.frames = 10;
  o.width = 640;
  o.height = 480;
  o.orbit_deg = 9.0;
  o.threads = 2;
  Synthesizer synth(scene, o);
  std::vector<ar::SensorFrame> frames;
  for (int k = 0; k < o.frames; ++k) frames.push_back(synth.render(k));
  MemorySource source(frames);
  const OdometryResult r = estimate_trajectory(source);
  ASSERT_EQ(r.trajectory.size(), 10u);
  ASSERT_FALSE(r.reference.empty());
  const DriftReport d = compare_trajectories(r.trajectory, r.reference);
  EXPECT_EQ(d.compared, 10);
  EXPECT_LT(d.final_m, 0.01) << "the camera moves about " << (frames.back().world_from_camera->translation() -
                                                             frames.front().world_from_camera->translation()).norm()
                            << " m";
  EXPECT_LT(d.final_deg, 0.5);
  // and the comparison itself is not blind: a trajectory standing still drifts by the whole motion
  std::vector<ar::PoseSample> still;
  for (const auto& s : r.trajectory.samples()) still.push_back({s.time_s, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity()});
  EXPECT_GT(compare_trajectories(ar::Trajectory(still), r.reference).final_m, 0.1);
}

}  // namespace
}  // namespace artrace::io
