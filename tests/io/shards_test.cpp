// Sharded export, join and batch, run as a user runs them.
#include "../cli_util.h"
#include "../test_util.h"

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <fstream>
#include <iterator>
#include <thread>

namespace artrace::io {
namespace {

const std::string kRoom = (kRoot / "data/recordings/room").string();
const std::string kDemo = (kRoot / "data/ar/demo.json").string();

std::string bin() { return std::string(ARTRACE_BINARY); }

using ::artrace::test::read_pngs;

/// Runs a command; returns its exit status and what it printed (stdout and stderr).
int run_capture(const std::string& cmd, std::string& output, const std::filesystem::path& dir) {
  const auto log = dir / "command.log";
  const int status = run(cmd + " > " + log.string() + " 2>&1");
  output = ::artrace::test::read_file(log);
  return status;
}

/// A folder for a test, empty.
std::filesystem::path fresh(const std::string& name) {
  const auto dir = ::artrace::test::scratch_path(name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

std::string export_cmd(const std::filesystem::path& out, const std::string& frames = "") {
  return bin() + " export " + kRoom + " --scene " + kDemo + " -o " + out.string() + " -q" +
         (frames.empty() ? "" : " --frames " + frames);
}

/// No file or folder under the name, nor a .partial one beside it.
void expect_nothing_written(const std::filesystem::path& out) {
  EXPECT_FALSE(std::filesystem::exists(out)) << out;
  for (const auto& e : std::filesystem::directory_iterator(out.parent_path())) {
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << "left behind: " << e.path();
  }
}

TEST(Shards, ShardsJoinedAreTheWholeExportBitForBit) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_whole");
  ASSERT_EQ(run(export_cmd(dir / "whole") + " > /dev/null"), 0);
  const auto whole = read_pngs(dir / "whole");
  ASSERT_EQ(whole.size(), 30u) << "the bundled recording has 30 frames";
  // three shards, exported out of order, each from a fresh process
  for (const std::string r : {"20:30", "0:11", "11:20"}) {
    ASSERT_EQ(run(export_cmd(dir / ("shard_" + r.substr(0, r.find(':'))), r) + " > /dev/null"), 0) << r;
  }
  const std::string shards = (dir / "shard_0").string() + " " + (dir / "shard_20").string() + " " + (dir / "shard_11").string();
  ASSERT_EQ(run(bin() + " join " + shards + " -o " + (dir / "joined").string() + " -q > /dev/null"), 0);
  const auto joined = read_pngs(dir / "joined");
  ASSERT_EQ(joined.size(), whole.size());
  for (size_t k = 0; k < whole.size(); ++k) EXPECT_TRUE(joined[k] == whole[k]) << "frame " << k;
  // and encoded once into a clip with every frame
  ASSERT_EQ(run(bin() + " join " + shards + " -o " + (dir / "clip.mp4").string() + " -q > /dev/null"), 0);
  cv::VideoCapture clip((dir / "clip.mp4").string());
  ASSERT_TRUE(clip.isOpened());
  int frames = 0;
  for (cv::Mat f; clip.read(f);) ++frames;
  EXPECT_EQ(frames, 30);
  std::filesystem::remove_all(dir);
}

/// Each frame of a clip, decoded by OpenCV (FFmpeg's decoders, not the encoders that wrote it),
/// against the PNG it was encoded from: the PSNR of the worst frame, and the number of frames.
std::pair<double, int> clip_psnr(const std::filesystem::path& clip, const std::filesystem::path& frames, cv::Rect crop = {}) {
  cv::VideoCapture in(clip.string());
  EXPECT_TRUE(in.isOpened()) << clip;
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(frames))
    if (e.path().extension() == ".png") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  double worst = 1e9;
  int n = 0;
  for (cv::Mat f; in.read(f); ++n) {
    if (n >= static_cast<int>(files.size())) break;
    const cv::Mat png = cv::imread(files[n].string(), cv::IMREAD_COLOR);
    const cv::Mat decoded = crop.area() > 0 ? f(crop) : f;
    EXPECT_EQ(decoded.size(), png.size()) << clip << " frame " << n;
    if (decoded.size() != png.size()) return {0.0, n};
    worst = std::min(worst, cv::PSNR(decoded, png));
  }
  return {worst, n};
}

/// The clips join writes hold every frame of the PNGs, decoded by another library: H.264 (.mp4,
/// .mkv) and Motion JPEG (.avi), --crf trading size for fidelity, and a frame of odd size (padded
/// for 4:2:0) whose picture is intact in the decoded frame's top-left corner.
TEST(Shards, ClipsHoldTheFramesTheyWereEncodedFrom) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_clips");
  const auto frames = dir / "frames";
  ASSERT_EQ(run(export_cmd(frames) + " > /dev/null"), 0);
  auto join = [&](const std::filesystem::path& folder, const std::string& out, const std::string& extra) {
    return run(bin() + " join " + folder.string() + " -o " + (dir / out).string() + " -q " + extra + " > /dev/null");
  };
  ASSERT_EQ(join(frames, "default.mp4", ""), 0);
  ASSERT_EQ(join(frames, "fine.mkv", "--crf 10 --preset ultrafast"), 0);
  ASSERT_EQ(join(frames, "mjpeg.avi", ""), 0);
  const auto [mp4, mp4_frames] = clip_psnr(dir / "default.mp4", frames);
  const auto [fine, fine_frames] = clip_psnr(dir / "fine.mkv", frames);
  const auto [avi, avi_frames] = clip_psnr(dir / "mjpeg.avi", frames);
  EXPECT_EQ(mp4_frames, 30);
  EXPECT_EQ(fine_frames, 30);
  EXPECT_EQ(avi_frames, 30);
  std::printf("worst frame PSNR: default .mp4 %.1f dB, --crf 10 .mkv %.1f dB, .avi %.1f dB\n", mp4, fine, avi);
  EXPECT_GT(mp4, 30.0);
  EXPECT_GT(fine, mp4 + 2.0) << "a lower crf keeps more";
  EXPECT_GT(avi, 30.0);
  EXPECT_GT(std::filesystem::file_size(dir / "fine.mkv"), std::filesystem::file_size(dir / "default.mp4"));

  // the same frames cut to 319x239, as a shard of their own
  const auto odd = dir / "odd";
  std::filesystem::create_directories(odd);
  for (const auto& e : std::filesystem::directory_iterator(frames)) {
    if (e.path().extension() != ".png") continue;
    const cv::Mat img = cv::imread(e.path().string(), cv::IMREAD_COLOR);
    cv::imwrite((odd / e.path().filename()).string(), img(cv::Rect(0, 0, 319, 239)));
  }
  std::ifstream in(frames / "shard.json");
  nlohmann::json info = nlohmann::json::parse(in);
  info["width"] = 319;
  info["height"] = 239;
  std::ofstream(odd / "shard.json") << info.dump();
  ASSERT_EQ(join(odd, "odd.mp4", ""), 0);
  const auto [odd_psnr, odd_frames] = clip_psnr(dir / "odd.mp4", odd, cv::Rect(0, 0, 319, 239));
  EXPECT_EQ(odd_frames, 30);
  EXPECT_GT(odd_psnr, 30.0);
  std::filesystem::remove_all(dir);
}

TEST(Shards, JoinRefusesAMissingShardNamingTheFrames) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_missing");
  ASSERT_EQ(run(export_cmd(dir / "a", "0:10") + " > /dev/null"), 0);
  ASSERT_EQ(run(export_cmd(dir / "c", "20:30") + " > /dev/null"), 0);
  std::string out;
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / "c").string() + " -o " + (dir / "clip.mp4").string(), out, dir), 1);
  EXPECT_NE(out.find("frames 10-19 are missing"), std::string::npos) << out;
  expect_nothing_written(dir / "clip.mp4");
  // a shard's tail missing too: the range asked for is the whole recording
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " -o " + (dir / "frames").string(), out, dir), 1);
  EXPECT_NE(out.find("frames 10-29 are missing"), std::string::npos) << out;
  expect_nothing_written(dir / "frames");
  // unless the range is given
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " --frames 0:10 -o " + (dir / "frames").string(), out, dir), 0) << out;
  EXPECT_EQ(read_pngs(dir / "frames").size(), 10u);
  std::filesystem::remove_all(dir);
}

TEST(Shards, JoinRefusesOverlappingShards) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_overlap");
  ASSERT_EQ(run(export_cmd(dir / "a", "0:12") + " > /dev/null"), 0);
  ASSERT_EQ(run(export_cmd(dir / "b", "10:30") + " > /dev/null"), 0);
  std::string out;
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / "b").string() + " -o " + (dir / "clip.mp4").string(), out, dir), 1);
  EXPECT_NE(out.find("frames 10-11 are in both"), std::string::npos) << out;
  expect_nothing_written(dir / "clip.mp4");
  std::filesystem::remove_all(dir);
}

/// Shards of different exports are not joined: a shard records what makes its frames (the
/// recording, the scene's and the other input files' contents, the options that change a
/// picture), and join refuses shards that differ in any, naming the shard and what differs. Before,
/// shards of the same recording with another scene, or with shadows off, were joined into one
/// clip that changed its picture part-way. The thread count changes no picture, and is free.
TEST(Shards, JoinRefusesShardsOfDifferentExports) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_mixed");
  const auto other_scene = box_scene(dir / "other");
  ASSERT_EQ(run(export_cmd(dir / "a", "0:15") + " --threads 1 > /dev/null"), 0);
  ASSERT_EQ(run(export_cmd(dir / "b", "15:30") + " --threads 2 > /dev/null"), 0);
  ASSERT_EQ(run(bin() + " export " + kRoom + " --scene " + other_scene.string() + " -q --frames 15:30 -o " + (dir / "other_b").string() +
                " > /dev/null"),
            0);
  ASSERT_EQ(run(export_cmd(dir / "dark_b", "15:30") + " --no-shadows > /dev/null"), 0);
  // the same scene file, changed between the shards
  const auto edited = box_scene(dir / "edited");
  ASSERT_EQ(run(bin() + " export " + kRoom + " --scene " + edited.string() + " -q --frames 0:15 -o " + (dir / "edited_a").string() +
                " > /dev/null"),
            0);
  std::ofstream(edited, std::ios::app) << "\n";
  ASSERT_EQ(run(bin() + " export " + kRoom + " --scene " + edited.string() + " -q --frames 15:30 -o " +
                (dir / "edited_b").string() + " > /dev/null"),
            0);
  std::string out;
  const std::pair<std::string, std::string> refused[] = {
      {"other_b", "scene"}, {"dark_b", "no_shadows"}};
  for (const auto& [second, what] : refused) {
    EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / second).string() + " -o " + (dir / "clip.mp4").string(), out, dir), 1);
    EXPECT_NE(out.find((dir / second).string() + " is not a shard of the same export as " + (dir / "a").string() + ": its " + what + " differs"),
              std::string::npos)
        << out;
    expect_nothing_written(dir / "clip.mp4");
  }
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "edited_a").string() + " " + (dir / "edited_b").string() + " -o " + (dir / "clip.mp4").string(), out, dir), 1);
  EXPECT_NE(out.find((dir / "edited_b").string() + " is not a shard of the same export as " + (dir / "edited_a").string() + ": its scene differs"),
            std::string::npos)
      << out;
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / "b").string() + " -o " + (dir / "clip.mp4").string(), out, dir), 0)
      << out;
  std::filesystem::remove_all(dir);
}

/// A join that fails part-way (a shard's frame unreadable) leaves nothing; so does a shard that
/// never finished (a .partial folder without shard.json), which is refused by name.
TEST(Shards, InterruptedJoinAndUnfinishedShardLeaveNothing) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_broken");
  ASSERT_EQ(run(export_cmd(dir / "a", "0:15") + " > /dev/null"), 0);
  ASSERT_EQ(run(export_cmd(dir / "b", "15:30") + " > /dev/null"), 0);
  std::ofstream(dir / "b" / "frame_000020.png", std::ios::trunc) << "not a PNG";
  std::string out;
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / "b").string() + " -o " + (dir / "clip.mp4").string(), out, dir), 1);
  EXPECT_NE(out.find("frame_000020.png"), std::string::npos) << out;
  expect_nothing_written(dir / "clip.mp4");
  std::filesystem::remove(dir / "b" / "shard.json");  // as an export stopped before the end leaves it
  EXPECT_EQ(run_capture(bin() + " join " + (dir / "a").string() + " " + (dir / "b").string() + " -o " + (dir / "frames").string(), out, dir), 1);
  EXPECT_NE(out.find("not a complete shard"), std::string::npos) << out;
  expect_nothing_written(dir / "frames");
  std::filesystem::remove_all(dir);
}

TEST(Shards, FrameRangesAreCheckedByName) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_shards_ranges");
  std::string out;
  EXPECT_EQ(run_capture(export_cmd(dir / "x", "5:3"), out, dir), 1);
  EXPECT_NE(out.find("\"5:3\" is empty"), std::string::npos) << out;
  EXPECT_EQ(run_capture(export_cmd(dir / "x", "a:3"), out, dir), 1);
  EXPECT_NE(out.find("\"a\" is not a frame number"), std::string::npos) << out;
  EXPECT_EQ(run_capture(export_cmd(dir / "x", "0:31"), out, dir), 1);
  EXPECT_NE(out.find("has 30 frames"), std::string::npos) << out;
  expect_nothing_written(dir / "x");
  std::filesystem::remove_all(dir);
}

TEST(Batch, ManifestJobsRunSideBySideAndJoin) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_batch");
  std::ofstream(dir / "jobs.json") << R"({"jobs": [
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "out/a", "frames": "0:6"},
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "out/b", "frames": "6:12"},
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "out/c.mp4", "frames": "0:4", "args": ["--no-shadows"]}]})";
  std::string out;
  ASSERT_EQ(run_capture(bin() + " batch " + (dir / "jobs.json").string() + " --parallel 2", out, dir), 0) << out;
  EXPECT_NE(out.find("3 done, 0 skipped, 0 failed"), std::string::npos) << out;
  ASSERT_EQ(run(export_cmd(dir / "whole", "0:12") + " > /dev/null"), 0);
  ASSERT_EQ(run(bin() + " join " + (dir / "out/a").string() + " " + (dir / "out/b").string() + " --frames 0:12 -o " +
                (dir / "joined").string() + " -q > /dev/null"),
            0);
  EXPECT_TRUE(read_pngs(dir / "joined") == read_pngs(dir / "whole"));
  EXPECT_TRUE(std::filesystem::exists(dir / "out/c.mp4"));
  // one entry, as an array task runs it; a done one is skipped
  ASSERT_EQ(run_capture(bin() + " batch " + (dir / "jobs.json").string() + " --index 1 --skip-done", out, dir), 0) << out;
  EXPECT_NE(out.find("job 1 already done"), std::string::npos) << out;
  // a job that fails is named, and the batch fails
  std::ofstream(dir / "bad.json") << R"({"jobs": [{"recording": "nowhere", "scene": ")" << kDemo << R"(", "output": "x.mp4"}]})";
  EXPECT_EQ(run_capture(bin() + " batch " + (dir / "bad.json").string(), out, dir), 1);
  EXPECT_NE(out.find("jobs 0 failed"), std::string::npos) << out;
  // a manifest error names the file, the entry and the key
  std::ofstream(dir / "typo.json") << R"({"jobs": [{"recording": "r", "scene": "s", "output": "o", "frame": "0:3"}]})";
  EXPECT_EQ(run_capture(bin() + " batch " + (dir / "typo.json").string(), out, dir), 1);
  EXPECT_NE(out.find("typo.json: jobs[0]: unknown key \"frame\""), std::string::npos) << out;
  // two jobs writing the same output (the second overwrote the first, or with --parallel both
  // wrote it at once): refused before any job runs
  std::ofstream(dir / "twice.json") << R"({"jobs": [
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "same/a", "frames": "0:2"},
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "same/b", "frames": "2:4"},
      {"recording": ")" << kRoom << R"(", "scene": ")" << kDemo << R"(", "output": "./same//a/", "frames": "4:6"}]})";
  EXPECT_EQ(run_capture(bin() + " batch " + (dir / "twice.json").string(), out, dir), 1);
  EXPECT_NE(out.find("twice.json: jobs[2]: output \"./same//a/\" is also jobs[0]'s: each job needs an output of its own"),
            std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "same")) << "no job ran";
  std::filesystem::remove_all(dir);
}

/// A batch stopped by a signal sent to it alone (kill's SIGTERM) passes it on to its running
/// jobs, which remove their partial outputs, and fails naming the signal. Before, the batch died and
/// its exports ran on, orphaned, and wrote their outputs.
TEST(Batch, StoppedBatchStopsItsJobs) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = fresh("artrace_batch_stop");
  const auto rec = dir / "rec";
  synth_room(rec, 120, 320, 240);
  std::ofstream(dir / "jobs.json") << R"({"jobs": [
      {"recording": "rec", "scene": ")" << kDemo << R"(", "output": "a.avi", "args": ["--side-by-side"]},
      {"recording": "rec", "scene": ")" << kDemo << R"(", "output": "b", "args": ["--side-by-side"]}]})";
  const auto log = dir / "log.txt", rc = dir / "rc.txt";
  // the batch in the background, SIGTERM to its process alone, its status kept
  ASSERT_EQ(run("cd " + dir.string() + " && { " + bin() + " batch jobs.json --parallel 2 --threads 1 > " + log.string() +
                " 2>&1 & p=$!; sleep 1; kill -TERM $p; wait $p; echo $? > " + rc.string() + "; }"),
            0);
  EXPECT_EQ(::artrace::test::read_file(rc), "1\n") << ::artrace::test::read_file(log);
  EXPECT_NE(::artrace::test::read_file(log).find("batch: stopped by SIGTERM: jobs 0, 1 stopped"), std::string::npos)
      << ::artrace::test::read_file(log);
  // an orphaned export of these would finish within a few seconds; none does
  std::this_thread::sleep_for(std::chrono::seconds(4));
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    EXPECT_TRUE(name == "rec" || name == "jobs.json" || name == "log.txt" || name == "rc.txt") << name << " left behind";
  }
}

}  // namespace
}  // namespace artrace::io
