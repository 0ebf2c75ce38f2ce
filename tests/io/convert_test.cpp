// artrace convert as a user runs it: a real Kinect recording (16zT depth, JPEG colour) to a TUM
// folder and back to ONI keeps every frame bit for bit (depth values, colour bytes, timestamps).
#include "../cli_util.h"
#include "artrace/io/recording.h"
#include "../test_util.h"

namespace artrace::io {
namespace {

std::vector<ar::SensorFrame> all_frames(const std::filesystem::path& p) {
  auto src = open_recording(p);
  std::vector<ar::SensorFrame> out;
  for (ar::SensorFrame f; src->next(f);) out.push_back(f);
  return out;
}

void expect_same_frames(const std::vector<ar::SensorFrame>& a, const std::vector<ar::SensorFrame>& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].depth.depth_m, b[k].depth.depth_m) << what << ": depth of frame " << k;
    EXPECT_EQ(a[k].color.rgb, b[k].color.rgb) << what << ": colour of frame " << k;
    EXPECT_NEAR(a[k].color_time_s, b[k].color_time_s, 1e-9) << what << ": frame " << k;
    EXPECT_NEAR(a[k].depth_time_s, b[k].depth_time_s, 1e-9) << what << ": frame " << k;
  }
}

TEST(Convert, RealOniToTumAndBackKeepsEveryFrame) {
  ARTRACE_REQUIRE_BINARY();
  ARTRACE_REQUIRE_SHARED("rgbd/oni-kinect1-tabletop-4f/Captured.oni");
  const auto dir = ::artrace::test::scratch_path("artrace_convert");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto tum = dir / "tum", oni = dir / "back.oni";
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " convert " + shared_path.string() + " -o " + tum.string() + " > /dev/null"), 0);
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " convert " + tum.string() + " -o " + oni.string() + " > /dev/null"), 0);
  const auto original = all_frames(shared_path);
  ASSERT_EQ(original.size(), 4u);
  size_t valid = 0;
  for (const float d : original[0].depth.depth_m) valid += d > 0.0f;
  ASSERT_EQ(valid, 219609u) << "the first frame as decoded from 16zT";
  expect_same_frames(original, all_frames(tum), "TUM folder");
  expect_same_frames(original, all_frames(oni), "ONI written back");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io

namespace artrace::io {
namespace {

/// A conversion or a synthetic recording stopped by a signal (Ctrl-C's SIGINT, kill's and Slurm's
/// SIGTERM, a closed terminal's SIGHUP) says so and leaves nothing behind: neither the output nor
/// its partial folder or file.
TEST(Convert, StoppedConversionOrSynthesisLeavesNoFile) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_convert_stop");
  std::filesystem::remove_all(dir);
  const auto big = dir / "big";
  synth_room(big, 120, 320, 240);
  const auto log = dir / "log.txt";
  const std::string aff = (kRoot / "data/scenes/room.aff").string();
  const std::tuple<const char*, const char*, std::string> runs[] = {
      {"TERM", "tum", "convert " + big.string()},
      {"INT", "converted", "convert " + big.string()},
      {"HUP", "synth_tum", "synth --scene " + aff + " --frames 100000 --width 64 --height 48 --threads 1"},
      {"TERM", "synth.oni", "synth --scene " + aff + " --frames 100000 --width 64 --height 48 --threads 1"},
  };
  for (const auto& [signal, name, args] : runs) {
    const auto out = dir / name;
    // once the first frame is written
    const std::string partial = out.string() + ".partial";
    const std::string ready = out.extension() == ".oni" ? "[ -s " + partial + " ]" : "ls " + partial + "/rgb/*.png > /dev/null 2>&1";
    const int st = run_until(std::string(ARTRACE_BINARY) + " " + args + " -o " + out.string(), ready, signal, log);
    EXPECT_EQ(st, 1) << signal << " " << name << ": " << ::artrace::test::read_file(log);
    EXPECT_NE(::artrace::test::read_file(log).find("stopped by SIG" + std::string(signal) + ": " + out.string() + " was not written"),
              std::string::npos)
        << ::artrace::test::read_file(log);
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      EXPECT_EQ(e.path().filename().string().rfind(name, 0), std::string::npos) << signal << ": " << e.path() << " left behind";
    }
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
