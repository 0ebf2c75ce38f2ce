// The replay viewer as a user runs it: under a virtual display (Xvfb) its view shows the overlay and
// its keys pause, step, seek and switch views; without a display it says so and points to export.
#include "../cli_util.h"
#include "../test_util.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <thread>

namespace artrace::io {
namespace {

/// Runs a shell command and returns its exit status and what it printed (stdout and stderr).
std::pair<int, std::string> run_capture(const std::string& cmd, const std::filesystem::path& log) {
  const int status = run(cmd + " > " + log.string() + " 2>&1");
  std::ifstream f(log);
  std::stringstream ss;
  ss << f.rdbuf();
  return {status, ss.str()};
}

bool have_xvfb() { return run("command -v Xvfb > /dev/null 2>&1") == 0; }

class Replay : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(ARTRACE_BINARY)) GTEST_SKIP() << "the artrace program is not built (tools off)";
    // each test its own folder and X server: ctest runs them in parallel
    const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    dir_ = ::artrace::test::scratch_path("artrace_replay_" + name);
    std::filesystem::remove_all(dir_);
    scene_ = box_scene(dir_);
  }
  void TearDown() override {
    if (!xvfb_pid_.empty()) run("kill " + xvfb_pid_);
    std::filesystem::remove_all(dir_);
  }

  /// Starts Xvfb on a free display number (it reports the number it took through -displayfd).
  void start_xvfb() {
    const auto number = dir_ / "display", pid = dir_ / "xvfb.pid";
    ASSERT_EQ(run("Xvfb -displayfd 3 -screen 0 1600x900x24 -nolisten tcp 3> " + number.string() + " 2>/dev/null & echo $! > " +
                  pid.string()),
              0);
    std::ifstream(pid) >> xvfb_pid_;
    for (int i = 0; i < 100 && display_.empty(); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      std::ifstream f(number);
      std::string n;
      if (f >> n) display_ = ":" + n;
    }
    ASSERT_FALSE(display_.empty()) << "Xvfb did not start";
  }

  /// replay under Xvfb with the given keys; returns the saved view and what the program printed
  std::pair<cv::Mat, std::string> replay(const std::string& keys, int frames) {
    const auto shot = dir_ / "shot.png";
    std::filesystem::remove(shot);
    const auto [status, out] = run_capture(
        "DISPLAY=" + display_ + " " + std::string(ARTRACE_BINARY) + " replay " +
            (kRoot / "data/recordings/room").string() + " --scene " + scene_.string() + " --threads 2 --frames " +
            std::to_string(frames) + " --keys '" + keys + "' --screenshot " + shot.string(),
        dir_ / "log.txt");
    EXPECT_EQ(status, 0) << out;
    return {cv::imread(shot.string()), out};
  }

  std::filesystem::path dir_, scene_;
  std::string xvfb_pid_, display_;
};

TEST_F(Replay, WithoutADisplaySaysSoAndPointsToExport) {
  const auto [status, out] = run_capture("env -u DISPLAY -u WAYLAND_DISPLAY " + std::string(ARTRACE_BINARY) + " replay " +
                                             (kRoot / "data/recordings/room").string() + " --scene " + scene_.string(),
                                         dir_ / "log.txt");
  EXPECT_EQ(status, 1);
  EXPECT_NE(out.find("no display"), std::string::npos) << out;
  EXPECT_NE(out.find("artrace export"), std::string::npos) << out;
  // an X display that does not answer is refused the same way, not with a crash
  const auto [status2, out2] = run_capture("env DISPLAY=:97 " + std::string(ARTRACE_BINARY) + " replay " +
                                               (kRoot / "data/recordings/room").string() + " --scene " + scene_.string(),
                                           dir_ / "log.txt");
  EXPECT_EQ(status2, 1);
  EXPECT_NE(out2.find("cannot open display"), std::string::npos) << out2;
}

TEST_F(Replay, UnderXvfbTheViewShowsTheOverlayAndTheHeadUpDisplay) {
  if (!have_xvfb()) GTEST_SKIP() << "Xvfb not installed (scripts/install-deps.sh installs it)";
  start_xvfb();
  const auto [view, out] = replay("", 6);
  ASSERT_FALSE(view.empty()) << out;
  // the 320x240 recording is shown twice as large
  ASSERT_EQ(view.cols, 640);
  ASSERT_EQ(view.rows, 480);
  const cv::Vec3b box = view.at<cv::Vec3b>(270, 252);  // the green box (BGR), as in the export test
  EXPECT_GT(box[1], 150);
  EXPECT_LT(box[0], 80);
  EXPECT_LT(box[2], 80);
  const cv::Vec3b wall = view.at<cv::Vec3b>(200, 600);  // the recording's wall, untouched
  EXPECT_GT(wall[1], 120);
  EXPECT_LT(std::abs(wall[0] - wall[2]), 40);
  // the head-up display: white text on a darkened band at the top
  cv::Mat band = view(cv::Rect(0, 0, 640, 50)), gray;
  cv::cvtColor(band, gray, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(gray > 230), 300) << "text of the head-up display";
  EXPECT_NE(out.find("6 views shown, stopped on frame 6/30"), std::string::npos) << out;
}

TEST_F(Replay, KeysPauseStepSeekAndSwitchViews) {
  if (!have_xvfb()) GTEST_SKIP() << "Xvfb not installed (scripts/install-deps.sh installs it)";
  start_xvfb();
  // pause, step twice, one back: frame 2
  EXPECT_NE(replay(" nnp", 5).second.find("stopped on frame 2/30"), std::string::npos);
  // seek one second (30 frames at 30 Hz) forward, clamped to the last frame, then back
  EXPECT_NE(replay(" ]", 3).second.find("stopped on frame 30/30"), std::string::npos);
  EXPECT_NE(replay(" ][", 4).second.find("stopped on frame 1/30"), std::string::npos);
  // depth view: no green box there any more
  const cv::Mat depth = replay(" d", 3).first;
  ASSERT_EQ(depth.cols, 640);
  const cv::Vec3b px = depth.at<cv::Vec3b>(270, 252);
  EXPECT_FALSE(px[1] > 150 && px[0] < 80 && px[2] < 80);
  // side by side: composite, original and depth, 960 wide
  const cv::Mat side = replay(" b", 3).first;
  ASSERT_EQ(side.cols, 960);
  ASSERT_EQ(side.rows, 240);
  const cv::Vec3b left = side.at<cv::Vec3b>(135, 126), middle = side.at<cv::Vec3b>(135, 126 + 320);
  EXPECT_GT(left[1], 150);
  EXPECT_FALSE(middle[1] > 150 && middle[0] < 80 && middle[2] < 80) << "the original has no box";
}

/// The soak as scripts/soak.sh runs it, made short: the recording looped at full speed, a sample
/// every 8 views. The CSV holds one row a sample, and the verdict in the JSON is worked out again
/// here from the CSV: growth = (largest resident memory after the warm-up - the warm-up's) / the
/// warm-up's, drift = the last quarter's median time against the first quarter's after the warm-up.
TEST_F(Replay, SoakSamplesMemoryAndTimeAndJudgesThem) {
  if (!have_xvfb()) GTEST_SKIP() << "Xvfb not installed (scripts/install-deps.sh installs it)";
  start_xvfb();
  const auto prefix = dir_ / "soak", json_path = dir_ / "replay.json";
  const auto [status, out] = run_capture("DISPLAY=" + display_ + " " + std::string(ARTRACE_BINARY) + " replay " +
                                             (kRoot / "data/recordings/room").string() + " --scene " + scene_.string() +
                                             " --threads 2 --loop --speed 100 --frames 80 --soak " + prefix.string() +
                                             " --soak-every 8 --json " + json_path.string(),
                                         dir_ / "log.txt");
  ASSERT_EQ(status, 0) << out;
  // 80 views of a 30-frame recording looped: the third pass stops on its 20th frame
  EXPECT_NE(out.find("80 views shown, stopped on frame 20/30"), std::string::npos) << out;
  std::ifstream csv(prefix.string() + ".csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "view,resident_mb,view_ms_median");
  std::vector<double> views, rss, ms;
  while (std::getline(csv, line)) {
    double v = 0, r = 0, m = 0;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf", &v, &r, &m), 3) << line;
    views.push_back(v);
    rss.push_back(r);
    ms.push_back(m);
  }
  ASSERT_EQ(views.size(), 10u);
  for (size_t i = 0; i < views.size(); ++i) {
    EXPECT_EQ(views[i], 8.0 * (i + 1));
    EXPECT_GT(rss[i], 10.0) << "resident MB";
    EXPECT_GT(ms[i], 0.0);
  }
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(json_path));
  EXPECT_EQ(j["views"], 80);
  const nlohmann::json& soak = j["soak"];
  // 10 samples: the first (a tenth) is the warm-up; 9 after it, quarters of 2
  const double warm = rss[1], largest = *std::max_element(rss.begin() + 1, rss.end());
  EXPECT_NEAR(soak["memory_growth"].get<double>(), (largest - warm) / warm, 1e-3);
  const double first = 0.5 * (ms[1] + ms[2]), last = 0.5 * (ms[8] + ms[9]);
  EXPECT_NEAR(soak["frame_ms_first_quarter"].get<double>(), first, 2e-3);
  EXPECT_NEAR(soak["frame_ms_last_quarter"].get<double>(), last, 2e-3);
  EXPECT_NEAR(soak["frame_time_drift"].get<double>(), (last - first) / first, 1e-3);
  for (const char* png : {"_memory.png", "_frame_time.png"}) {
    const cv::Mat plot = cv::imread(prefix.string() + png);
    EXPECT_FALSE(plot.empty()) << png;
  }
}

}  // namespace
}  // namespace artrace::io
