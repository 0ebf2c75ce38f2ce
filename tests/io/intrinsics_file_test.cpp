// Intrinsics from the files people have (Open3D JSON, OpenCV and ROS YAML), the warnings when
// none is found, and undistortion with a file's distortion coefficients.
#include "artrace/io/intrinsics_file.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/recording.h"
#include "../test_util.h"

#include <opencv2/imgcodecs.hpp>

#include <fstream>

namespace artrace::io {
namespace {

std::filesystem::path write_file(const std::string& name, const std::string& text) {
  const auto dir = ::artrace::test::scratch_path("artrace_intrinsics");
  std::filesystem::create_directories(dir);
  std::ofstream(dir / name) << text;
  return dir / name;
}

TEST(CameraFile, Open3dPinholeCameraIntrinsicIsColumnMajor) {
  const auto p = write_file("OPEN3D.JSON", R"({ "width": 640, "height": 480,
      "intrinsic_matrix": [600.0, 0.0, 0.0, 0.0, 601.0, 0.0, 320.5, 240.25, 1.0] })");  // any case
  const CameraFile c = read_camera_file(p);
  EXPECT_DOUBLE_EQ(c.intrinsics.fx, 600.0);
  EXPECT_DOUBLE_EQ(c.intrinsics.fy, 601.0);
  EXPECT_DOUBLE_EQ(c.intrinsics.cx, 320.5);
  EXPECT_DOUBLE_EQ(c.intrinsics.cy, 240.25);
  EXPECT_EQ(c.intrinsics.width, 640);
  EXPECT_EQ(c.intrinsics.height, 480);
  EXPECT_TRUE(c.distortion.empty());
}

TEST(CameraFile, OpenCvAndRosYaml) {
  const auto cv_file = write_file("opencv.yaml", R"(%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 517.3, 0., 318.6, 0., 516.5, 255.3, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0.2624, -0.9531, -0.0054, 0.0026, 1.1633 ]
)");
  const CameraFile a = read_camera_file(cv_file);
  EXPECT_DOUBLE_EQ(a.intrinsics.fx, 517.3);
  EXPECT_DOUBLE_EQ(a.intrinsics.cy, 255.3);
  EXPECT_EQ(a.intrinsics.width, 640);
  ASSERT_EQ(a.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(a.distortion[4], 1.1633);
  const auto ros_file = write_file("ros.yaml", R"(image_width: 320
image_height: 240
camera_name: kinect
camera_matrix:
  rows: 3
  cols: 3
  data: [285.17, 0, 160, 0, 285.17, 120, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0, 0, 0, 0, 0]
)");
  const CameraFile b = read_camera_file(ros_file);
  EXPECT_DOUBLE_EQ(b.intrinsics.fx, 285.17);
  EXPECT_DOUBLE_EQ(b.intrinsics.cx, 160.0);
  EXPECT_EQ(b.intrinsics.height, 240);
  EXPECT_EQ(b.distortion, std::vector<double>(5, 0.0));
}

TEST(CameraFile, BrokenFilesNameTheFileAndTheProblem) {
  struct Case {
    const char* name;
    const char* text;
    const char* message;
  };
  const Case cases[] = {
      {"no_matrix.json", R"({ "width": 640 })", "intrinsic_matrix"},
      {"short.json", R"({ "intrinsic_matrix": [1, 2, 3] })", "expected 9 numbers"},
      {"skew.json", R"({ "intrinsic_matrix": [500, 3, 0, 0, 500, 0, 320, 240, 1] })", "not a pinhole camera matrix"},
      {"zero_fx.json", R"({ "intrinsic_matrix": [0, 0, 0, 0, 500, 0, 320, 240, 1] })", "fx 0 is not in (0, 1e6]"},
      {"not_json.json", "{ intrinsic", "not valid JSON"},
      {"no_matrix.yaml", "image_width: 640\n", "has neither camera_matrix nor K"},
      {"huge.yaml", "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [1e9, 0, 1, 0, 1, 1, 0, 0, 1]\n", "fx 1e+09 is not in (0, 1e6]"},
      // found by fuzz_intrinsics: a width beyond int was converted to int (undefined behaviour)
      {"huge_width.yaml", "image_width: 1e308\nimage_height: 240\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [285, 0, 160, 0, 285, 120, 0, 0, 1]\n",
       "image_width 1e+308 is not a whole number in 0..100000"},
      // found by fuzz_intrinsics: OpenCV's matrix reader allocated rows x cols as declared (48 GB)
      // before looking at the data, which here is no sequence of numbers
      {"huge_rows.yaml", "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 1000000000\n   cols: 3\n   dt: d\n   data: x\n",
       "camera_matrix: expected 9 numbers (a 3x3 matrix), got 0"},
      {"half_height.yaml", "image_width: 320\nimage_height: 239.5\nK: [285, 0, 160, 0, 285, 120, 0, 0, 1]\n", "image_height 239.5 is not a whole number"},
      {"huge_width.json", R"({ "intrinsic_matrix": [500, 0, 0, 0, 500, 0, 320, 240, 1], "width": 1e300, "height": 480 })",
       "width 1e+300 is not a whole number in 0..100000"},
  };
  for (const Case& c : cases) {
    const auto p = write_file(c.name, c.text);
    try {
      read_camera_file(p);
      ADD_FAILURE() << c.name << " was accepted";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(c.message), std::string::npos) << c.name << ": " << e.what();
    }
  }
}

/// An image folder of one frame: a black colour image with a white dot, flat depth.
std::filesystem::path dot_folder(const std::string& name, int x, int y) {
  const auto dir = ::artrace::test::scratch_path(name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "color");
  std::filesystem::create_directories(dir / "depth");
  cv::Mat c(240, 320, CV_8UC3, cv::Scalar(0, 0, 0));
  c.at<cv::Vec3b>(y, x) = cv::Vec3b(255, 255, 255);
  cv::imwrite((dir / "color/0.png").string(), c);
  cv::imwrite((dir / "depth/0.png").string(), cv::Mat(240, 320, CV_16UC1, cv::Scalar(1500)));
  return dir;
}

TEST(CameraFile, ImageFolderWithoutIntrinsicsWarnsNamingTheDefaults) {
  const auto dir = dot_folder("artrace_no_intrinsics", 10, 10);
  RecordingOptions mm;  // the depth units given: the intrinsics are all that is assumed
  mm.depth_units_per_metre = 1000.0;
  auto src = open_recording(dir, mm);
  ASSERT_EQ(src->warnings().size(), 1u);
  EXPECT_NE(src->warnings()[0].find("default intrinsics fx = fy = 525 px at 640 wide"), std::string::npos) << src->warnings()[0];
  EXPECT_EQ(src->intrinsics_source(), "defaults");
  std::ofstream(dir / "intrinsics.json") << R"({ "width": 320, "height": 240, "intrinsic_matrix": [300, 0, 0, 0, 300, 0, 160, 120, 1] })";
  auto with = open_recording(dir, mm);
  EXPECT_TRUE(with->warnings().empty());
  EXPECT_EQ(with->intrinsics_source(), (dir / "intrinsics.json").string());
  ar::SensorFrame f;
  ASSERT_TRUE(with->next(f));
  EXPECT_DOUBLE_EQ(f.color_intrinsics.fx, 300.0);
  EXPECT_DOUBLE_EQ(f.depth_intrinsics.cy, 120.0);
  EXPECT_FLOAT_EQ(f.depth.at(5, 5), 1.5f) << "image folders hold millimetres";
  std::filesystem::remove_all(dir);
}

/// Distortion coefficients in a camera file undistort the frames: a dot seen at the distorted
/// position of an undistorted point p lands on p. The distorted position is worked out here with
/// the Brown-Conrady model (k1, k2, p1, p2), independently of OpenCV's undistortion.
TEST(CameraFile, DistortionCoefficientsUndistortTheFrames) {
  const double fx = 300, fy = 300, cx = 160, cy = 120, k1 = -0.25, k2 = 0.08, p1 = 0.001, p2 = -0.002;
  const double u = 260, v = 60;  // where the dot belongs
  const double x = (u - cx) / fx, y = (v - cy) / fy, r2 = x * x + y * y, radial = 1 + k1 * r2 + k2 * r2 * r2;
  const double xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  const int ud = static_cast<int>(std::lround(fx * xd + cx)), vd = static_cast<int>(std::lround(fy * yd + cy));
  const auto dir = dot_folder("artrace_distorted", ud, vd);
  std::ofstream(dir / "camera.yaml") << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [300, 0, 160, 0, 300, 120, 0, 0, 1]\n"
                                     << "distortion_coefficients:\n  rows: 1\n  cols: 4\n  data: [" << k1 << ", " << k2 << ", " << p1 << ", " << p2
                                     << "]\n";
  auto src = open_recording(dir);
  EXPECT_NE(src->intrinsics_source().find("undistorted"), std::string::npos);
  ar::SensorFrame f;
  ASSERT_TRUE(src->next(f));
  // the brightest pixel
  int best = -1, bx = 0, by = 0;
  for (int yy = 0; yy < f.color.height; ++yy)
    for (int xx = 0; xx < f.color.width; ++xx)
      if (f.color.at(xx, yy)[0] > best) best = f.color.at(xx, yy)[0], bx = xx, by = yy;
  EXPECT_GT(best, 40);
  EXPECT_NEAR(bx, u, 1.0) << "the dot was at " << ud << "," << vd << " in the distorted image";
  EXPECT_NEAR(by, v, 1.0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
