// The export command as a user runs it: the clip read back with OpenCV, and no file left behind
// when an export stops early.
#include "../cli_util.h"

#include <opencv2/videoio.hpp>

#include <fstream>

namespace artrace::io {
namespace {

TEST(Export, ClipReadsBackWithTheOverlayWhereTheObjectIs) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = std::filesystem::temp_directory_path() / "artrace_export";
  std::filesystem::remove_all(dir);
  const auto scene = box_scene(dir);
  const auto clip = dir / "clip.avi";
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " +
                scene.string() + " -o " + clip.string() + " --no-shadows -q > /dev/null"),
            0);
  cv::VideoCapture cap(clip.string());
  ASSERT_TRUE(cap.isOpened());
  int frames = 0, green = 0, recorded = 0;
  cv::Mat img;
  while (cap.read(img)) {
    ++frames;
    ASSERT_EQ(img.cols, 320);
    ASSERT_EQ(img.rows, 240);
    const cv::Vec3b box = img.at<cv::Vec3b>(135, 126);      // where the green box stands all along (BGR)
    const cv::Vec3b wall = img.at<cv::Vec3b>(30, 300);      // the room's wall, untouched
    green += box[1] > 150 && box[0] < 80 && box[2] < 80;
    recorded += std::abs(wall[0] - wall[2]) < 40 && wall[1] > 120;
  }
  EXPECT_EQ(frames, 30);
  EXPECT_GE(green, 25) << "the virtual box's colour where it stands";
  EXPECT_EQ(recorded, frames) << "the recording's colour elsewhere";
  std::filesystem::remove_all(dir);
}

TEST(Export, StoppedExportLeavesNoFile) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = std::filesystem::temp_directory_path() / "artrace_export_stop";
  std::filesystem::remove_all(dir);
  const auto scene = box_scene(dir);
  // a recording whose 6th colour image is damaged: the export fails there
  const auto rec = dir / "rec";
  synth_room(rec, 10, 64, 48);
  std::vector<std::filesystem::path> colour;
  for (const auto& e : std::filesystem::directory_iterator(rec / "rgb")) colour.push_back(e.path());
  std::sort(colour.begin(), colour.end());
  std::ofstream(colour[5], std::ios::trunc) << "not a png";
  for (const char* out : {"clip.avi", "frames"}) {
    const auto path = dir / out;
    EXPECT_NE(run(std::string(ARTRACE_BINARY) + " export " + rec.string() + " --scene " + scene.string() + " -o " +
                  path.string() + " -q > /dev/null 2>&1"),
              0);
    EXPECT_FALSE(std::filesystem::exists(path)) << out;
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << e.path();
    }
  }
  // Ctrl-C during a long export
  const auto big = dir / "big";
  synth_room(big, 120, 320, 240);
  const auto clip = dir / "interrupted.avi";
  const int status = run("timeout -s INT 0.4 " + std::string(ARTRACE_BINARY) + " export " + big.string() + " --scene " +
                         scene.string() + " -o " + clip.string() + " --side-by-side --threads 1 -q > /dev/null 2>&1");
  EXPECT_NE(status, 0) << "the export was stopped";
  EXPECT_FALSE(std::filesystem::exists(clip));
  EXPECT_FALSE(std::filesystem::exists(dir / "interrupted.partial.avi"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
