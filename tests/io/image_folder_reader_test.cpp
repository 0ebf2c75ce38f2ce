#include "artrace/io/image_folder_reader.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/recording.h"
#include "../test_util.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <fstream>

namespace artrace::io {
namespace {

std::filesystem::path make_folder(const std::string& name, bool video, int frames) {
  const auto dir = ::artrace::test::scratch_path(name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "depth");
  if (!video) std::filesystem::create_directories(dir / "color");
  cv::VideoWriter writer;
  if (video) writer.open((dir / "color.avi").string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 15.0, cv::Size(32, 24));
  for (int k = 0; k < frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "%03d.png", k);
    const cv::Mat c(24, 32, CV_8UC3, cv::Scalar(20 * k, 100, 200));  // BGR
    if (video) writer.write(c);
    else cv::imwrite((dir / "color" / name).string(), c);
    cv::Mat d(24, 32, CV_16UC1, cv::Scalar(1000 + 100 * k));
    cv::imwrite((dir / "depth" / name).string(), d);
  }
  return dir;
}

TEST(ImageFolder, ImagePairsInOrderWithDepthInMetres) {
  const auto dir = make_folder("artrace_imgfolder", false, 4);
  std::ofstream(dir / "intrinsics.txt") << "# fx fy cx cy\n30 31 15.5 11.5\n";
  auto src = open_recording(dir);
  EXPECT_EQ(src->frame_count().value(), 4);
  ar::SensorFrame f;
  for (int k = 0; k < 4; ++k) {
    ASSERT_TRUE(src->next(f));
    EXPECT_FLOAT_EQ(f.depth.at(5, 5), 1.0f + 0.1f * k);
    EXPECT_EQ(f.color.at(0, 0)[2], 20 * k) << "blue, from BGR";
    EXPECT_DOUBLE_EQ(f.color_time_s, k / 30.0);
    EXPECT_EQ(f.color_intrinsics.fy, 31.0);
  }
  EXPECT_FALSE(src->next(f));
  const auto warned = [](const ar::FrameSource& s) {
    for (const std::string& w : s.warnings()) {
      if (w.find("depth units not given: read as millimetres") != std::string::npos) return true;
    }
    return false;
  };
  EXPECT_TRUE(warned(*src)) << "millimetres assumed, said";
  RecordingOptions given;
  given.depth_units_per_metre = 1000.0;
  EXPECT_FALSE(warned(*open_recording(dir, given))) << "nothing assumed";
  src->seek(2);
  ASSERT_TRUE(src->next(f));
  EXPECT_FLOAT_EQ(f.depth.at(0, 0), 1.2f);
  std::filesystem::remove(dir / "color" / "003.png");
  EXPECT_THROW(open_recording(dir), ParseError) << "3 colour images for 4 depth images";
  std::filesystem::remove_all(dir);
}

/// Numbers in file names count as numbers (0.png, 1.png, ..., 10.png: ten comes after nine, as
/// capture tools that do not pad their numbers mean it, not after one), and a frame whose colour
/// and depth names carry different numbers is paired by order with a warning naming both.
TEST(ImageFolder, NumberedNamesAreInNumericOrder) {
  const auto dir = ::artrace::test::scratch_path("artrace_imgfolder_numbers");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "color");
  std::filesystem::create_directories(dir / "depth");
  for (int k = 0; k < 12; ++k) {
    cv::imwrite((dir / "color" / ("color_" + std::to_string(k) + ".png")).string(), cv::Mat(4, 5, CV_8UC3, cv::Scalar(10 * k, 0, 0)));
    cv::imwrite((dir / "depth" / ("depth_" + std::to_string(k) + ".png")).string(), cv::Mat(4, 5, CV_16UC1, cv::Scalar(1000 + 100 * k)));
  }
  auto src = open_recording(dir);
  ar::SensorFrame f;
  for (int k = 0; k < 12; ++k) {
    ASSERT_TRUE(src->next(f));
    EXPECT_EQ(f.color.at(0, 0)[2], 10 * k) << "frame " << k;
    EXPECT_FLOAT_EQ(f.depth.at(0, 0), 1.0f + 0.1f * k) << "frame " << k;
  }
  for (const std::string& w : src->warnings()) EXPECT_EQ(w.find("pairs"), std::string::npos) << w;
  // depth numbered from 1: paired by order, said once
  std::filesystem::remove_all(dir / "depth");
  std::filesystem::create_directories(dir / "depth");
  for (int k = 1; k <= 12; ++k) {
    cv::imwrite((dir / "depth" / ("depth_" + std::to_string(k) + ".png")).string(), cv::Mat(4, 5, CV_16UC1, cv::Scalar(1000)));
  }
  const auto warnings = open_recording(dir)->warnings();
  EXPECT_EQ(std::count_if(warnings.begin(), warnings.end(), [&](const std::string& w) {
              return w.find((dir / "color" / "color_0.png").string() + " pairs with " + (dir / "depth" / "depth_1.png").string()) !=
                     std::string::npos;
            }),
            1);
  std::filesystem::remove_all(dir);
}

/// Depth images of another size than the colour images (an unregistered sensor's, or a folder put
/// together from two recordings) are refused, naming the depth image and both sizes: the
/// compositor reads a colour pixel's depth at the same pixel. So is an intrinsics.txt naming
/// another size than the images'.
TEST(ImageFolder, ImagesAndIntrinsicsOfAnotherSizeAreRefused) {
  const auto dir = make_folder("artrace_imgfolder_sizes", false, 2);
  auto refusal = [&]() -> std::string {
    try {
      auto src = open_recording(dir);
      ar::SensorFrame f;
      while (src->next(f)) {
      }
    } catch (const ParseError& e) {
      return e.what();
    }
    return "read";
  };
  std::ofstream(dir / "intrinsics.txt") << "30 31 15.5 11.5 32 24\n";
  EXPECT_EQ(refusal(), "read");
  std::ofstream(dir / "intrinsics.txt") << "30 31 15.5 11.5 64 48\n";
  EXPECT_NE(refusal().find((dir / "intrinsics.txt").string() + ": is for 64x48 images, the recording's are 32x24"), std::string::npos)
      << refusal();
  std::filesystem::remove(dir / "intrinsics.txt");
  cv::imwrite((dir / "depth" / "001.png").string(), cv::Mat(12, 16, CV_16UC1, cv::Scalar(1000)));
  EXPECT_NE(refusal().find((dir / "depth" / "001.png").string() + ": depth is 16x12, colour 32x24"), std::string::npos) << refusal();
  std::filesystem::remove_all(dir);
}

TEST(ImageFolder, ColourVideoWithDepthImagesSeeksFrameAccurately) {
  const auto dir = make_folder("artrace_vidfolder", true, 6);
  auto src = open_recording(dir);
  ASSERT_EQ(src->frame_count().value(), 6);
  ar::SensorFrame f;
  for (const int k : {4, 1, 5, 0}) {
    src->seek(k);
    ASSERT_TRUE(src->next(f));
    EXPECT_NEAR(f.color.at(10, 10)[2], 20 * k, 12) << "frame " << k << " (MJPEG is lossy)";
    EXPECT_FLOAT_EQ(f.depth.at(0, 0), 1.0f + 0.1f * k);
    EXPECT_DOUBLE_EQ(f.color_time_s, k / 15.0) << "the video's own rate";
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
