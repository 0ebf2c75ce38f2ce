#include "artrace/io/ar_scene.h"
#include "artrace/io/aff_scene.h"
#include "artrace/io/intrinsics_file.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/recording.h"
#include "artrace/io/text_file.h"
#include "artrace/io/tum_reader.h"
#include "../test_util.h"

#include <opencv2/imgcodecs.hpp>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <functional>

namespace artrace::io {
namespace {

TEST(Tum, AssociationPairsNearestUniqueWithinTolerance) {
  const std::vector<TimedFile> color{{1.000, "a"}, {1.033, "b"}, {1.066, "c"}, {1.100, "d"}};
  const std::vector<TimedFile> depth{{0.990, "A"}, {1.040, "B"}, {1.200, "C"}};
  const auto pairs = associate(color, depth, 0.02);
  // 1.000-0.990 (10 ms) and 1.033-1.040 (7 ms); 1.066 is 26 ms from B, 1.100 100 ms from C
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0], std::make_pair(size_t(0), size_t(0)));
  EXPECT_EQ(pairs[1], std::make_pair(size_t(1), size_t(1)));
  // one depth frame between two colour frames goes to the nearer one only
  const auto one = associate({{1.000, "a"}, {1.012, "b"}}, {{1.008, "A"}}, 0.02);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0].first, 1u);
}

/// The pairing window is max_dt_s on both sides of a colour frame, no more: a depth frame 19 ms
/// before or after pairs, one 21 ms (or 25, 40 ms) before or after does not.
TEST(Tum, PairingWindowHoldsOnBothSides) {
  for (const double side : {-1.0, 1.0}) {
    for (const double dt : {0.019, 0.021, 0.025, 0.040}) {
      const auto pairs = associate({{10.0, "c"}}, {{10.0 + side * dt, "d"}}, 0.02);
      EXPECT_EQ(pairs.size(), dt < 0.02 ? 1u : 0u) << "depth " << side * dt * 1000 << " ms from colour";
    }
  }
}

TEST(Tum, TrajectoryInterpolatesBetweenSamples) {
  ar::PoseSample a, b;
  a.time_s = 10.0;
  b.time_s = 11.0;
  b.translation = {2.0, 0.0, -4.0};
  b.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  const ar::Trajectory traj({a, b});
  const auto p = traj.at(10.25, 2.0);
  ASSERT_TRUE(p.has_value());
  EXPECT_NEAR(p->translation().x(), 0.5, 1e-12);
  EXPECT_NEAR(p->translation().z(), -1.0, 1e-12);
  const Eigen::AngleAxisd aa(p->rotation());
  EXPECT_NEAR(aa.angle(), M_PI / 8, 1e-9) << "slerp: a quarter of 90 degrees";
  EXPECT_NEAR(std::fabs(aa.axis().z()), 1.0, 1e-9);
  EXPECT_FALSE(traj.at(10.5, 0.5).has_value()) << "samples 1 s apart are a gap at max 0.5 s";
  EXPECT_FALSE(traj.at(9.0, 2.0).has_value()) << "before the first sample";
  EXPECT_TRUE(traj.at(11.0).has_value()) << "exactly on a sample";
}

/// A small sequence written here: values, association, poses at colour timestamps.
TEST(Tum, ReaderDeliversFramesInMetresWithPoses) {
  const auto dir = ::artrace::test::scratch_path("artrace_tum_ok");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "rgb");
  std::filesystem::create_directories(dir / "depth");
  std::ofstream rgb(dir / "rgb.txt"), dep(dir / "depth.txt"), gt(dir / "groundtruth.txt");
  rgb << "# colour\n";
  for (int k = 0; k < 3; ++k) {
    const double tc = 100.0 + 0.1 * k, td = tc + 0.004;
    rgb << std::fixed << tc << " rgb/" << k << ".png\n";
    dep << std::fixed << td << " depth/" << k << ".png\n";
    cv::Mat c(4, 5, CV_8UC3, cv::Scalar(10 * k, 20, 30));  // BGR
    cv::Mat d(4, 5, CV_16UC1, cv::Scalar(5000 * (k + 1)));
    d.at<uint16_t>(1, 1) = 0;
    d.at<uint16_t>(2, 2) = 65535;
    cv::imwrite((dir / "rgb" / (std::to_string(k) + ".png")).string(), c);
    cv::imwrite((dir / "depth" / (std::to_string(k) + ".png")).string(), d);
  }
  gt << "99.95 0 0 0 0 0 0 1\n100.25 3 0 0 0 0 0 1\n";
  rgb.close();
  dep.close();
  gt.close();
  TumOptions options;
  options.max_pose_gap_s = 0.5;  // the two samples are 0.3 s apart
  TumReader reader(dir, options);
  ASSERT_EQ(reader.frame_count().value(), 3);
  ar::SensorFrame f;
  for (int k = 0; k < 3; ++k) {
    ASSERT_TRUE(reader.next(f));
    EXPECT_FLOAT_EQ(f.depth.at(0, 0), static_cast<float>(k + 1));
    EXPECT_EQ(f.depth.at(1, 1), 0.0f) << "no reading";
    EXPECT_EQ(f.depth.at(2, 2), 0.0f) << "saturated 65535 is no reading either";
    EXPECT_EQ(f.color.at(0, 0)[0], 30) << "RGB order";
    EXPECT_EQ(f.color.at(0, 0)[2], 10 * k);
    ASSERT_TRUE(f.world_from_camera.has_value());
    // linear between (99.95, x=0) and (100.25, x=3): x = 10 (t - 99.95)
    EXPECT_NEAR(f.world_from_camera->translation().x(), 10.0 * (100.0 + 0.1 * k - 99.95), 1e-6);
    EXPECT_EQ(f.color_intrinsics.fx, 525.0 * 5 / 640) << "no name, no intrinsics.txt: the ROS default, scaled with the width";
  }
  EXPECT_FALSE(reader.next(f));
  reader.seek(1);
  ASSERT_TRUE(reader.next(f));
  EXPECT_EQ(f.index, 1);
  // a depth PNG with a text chunk declaring 1.85 GB after its header (libpng would allocate that
  // before reading it): refused with the file, the chunk and its place named
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(4, 5, CV_16UC1, cv::Scalar(5000)), png));
  const std::vector<uint8_t> itxt = {0x6e, 0x65, 0x74, 0x59, 'i', 'T', 'X', 't', 'a'};
  png.insert(png.begin() + 33, itxt.begin(), itxt.end());
  std::ofstream(dir / "depth" / "2.png", std::ios::binary).write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  try {
    reader.read(2);
    ADD_FAILURE() << "a broken PNG was read";
  } catch (const ParseError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find((dir / "depth" / "2.png").string() + ": the image is a broken PNG: its iTXt chunk at byte 33 declares 1852142681 bytes"),
              std::string::npos)
        << msg;
  }
  std::filesystem::remove_all(dir);
}

/// A TUM folder of `w` x `h` images (one frame), with `intrinsics` as its intrinsics.txt ("" for none).
std::filesystem::path tum_folder(const std::filesystem::path& dir, int w, int h, const std::string& intrinsics) {
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "rgb");
  std::filesystem::create_directories(dir / "depth");
  std::ofstream(dir / "rgb.txt") << "1.0 rgb/0.png\n";
  std::ofstream(dir / "depth.txt") << "1.0 depth/0.png\n";
  cv::imwrite((dir / "rgb" / "0.png").string(), cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 20, 30)));
  cv::imwrite((dir / "depth" / "0.png").string(), cv::Mat(h, w, CV_16UC1, cv::Scalar(5000)));
  if (!intrinsics.empty()) std::ofstream(dir / "intrinsics.txt") << intrinsics;
  return dir;
}

/// Intrinsics that name the size of the images they are for, and a recording whose images are of
/// another size (a sequence downscaled after calibration): the frames are refused with the file
/// and both sizes named, as a camera file given with --intrinsics is, instead of being projected
/// with a focal length and principal point for other images. The Freiburg intrinsics chosen by a
/// folder's name are for the benchmark's 640x480 images, and are refused on others the same way.
/// Without any, the default (525 px at 640 wide) is scaled with the width and centred, as an image
/// folder's is, with a warning.
TEST(Tum, IntrinsicsForImagesOfAnotherSizeAreRefused) {
  const auto root = ::artrace::test::scratch_path("artrace_tum_intrinsics_size");
  auto first_frame = [](const std::filesystem::path& dir) {
    ar::SensorFrame f;
    auto src = open_recording(dir);
    EXPECT_TRUE(src->next(f));
    return f;
  };
  auto refusal = [&](const std::filesystem::path& dir) -> std::string {
    try {
      first_frame(dir);
    } catch (const ParseError& e) {
      return e.what();
    }
    return "read";
  };
  const auto a = tum_folder(root / "a", 320, 240, "289.7 289.7 159.5 119.5 640 480\n");
  EXPECT_NE(refusal(a).find((a / "intrinsics.txt").string() + ": is for 640x480 images, the recording's are 320x240"),
            std::string::npos)
      << refusal(a);
  tum_folder(a, 320, 240, "289.7 289.7 159.5 119.5 320 240\n");
  EXPECT_DOUBLE_EQ(first_frame(a).color_intrinsics.fx, 289.7);
  tum_folder(a, 320, 240, "289.7 289.7 159.5 119.5\n");
  EXPECT_DOUBLE_EQ(first_frame(a).color_intrinsics.cx, 159.5) << "no size named: taken as the images'";

  const auto fr1 = tum_folder(root / "rgbd_dataset_freiburg1_small", 320, 240, "");
  const std::string msg = refusal(fr1);
  EXPECT_NE(msg.find(fr1.string() + ": the TUM benchmark's Freiburg 1 intrinsics, chosen by the folder's name, are for 640x480 images, "
                                    "the recording's are 320x240"),
            std::string::npos)
      << msg;
  tum_folder(fr1, 640, 480, "");
  EXPECT_DOUBLE_EQ(first_frame(fr1).color_intrinsics.fx, 517.3);

  const auto plain = tum_folder(root / "plain", 320, 240, "");
  const ar::SensorFrame f = first_frame(plain);
  EXPECT_DOUBLE_EQ(f.color_intrinsics.fx, 525.0 * 320 / 640);
  EXPECT_DOUBLE_EQ(f.color_intrinsics.fy, 525.0 * 320 / 640);
  EXPECT_DOUBLE_EQ(f.color_intrinsics.cx, 159.5);
  EXPECT_DOUBLE_EQ(f.color_intrinsics.cy, 119.5);
  const auto warnings = open_recording(plain)->warnings();
  EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("default intrinsics fx = fy = 525 px at 640 wide (scaled with the width), principal point at the centre") != std::string::npos;
  }));
  std::filesystem::remove_all(root);
}

/// intrinsics.txt (TUM and image folders): the first line that is not a comment, checked. Values
/// that parse but make no camera (a focal length of 0 or 1e39, a principal point at 1e20, a size
/// of 0 or 1e20, which was cast to int unchecked) are refused with the file, line and value named.
TEST(Intrinsics, ValuesOutOfRangeNameFileLineAndValue) {
  const auto dir = ::artrace::test::scratch_path("artrace_intrinsics");
  std::filesystem::create_directories(dir);
  const auto path = dir / "intrinsics.txt";
  std::ofstream(path) << "# fx fy cx cy width height\n\n500 510 319.5 239.5 640 480\n";
  const ar::PinholeIntrinsics k = read_intrinsics(path);
  EXPECT_EQ(k.fx, 500.0);
  EXPECT_EQ(k.fy, 510.0);
  EXPECT_EQ(k.cx, 319.5);
  EXPECT_EQ(k.cy, 239.5);
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
  std::ofstream(path) << "500 510 319.5 239.5\n";
  EXPECT_EQ(read_intrinsics(path).width, 0) << "no size given: the readers take the images'";
  const std::pair<const char*, const char*> cases[] = {
      {"0 510 319.5 239.5", ":1: fx \"0\" is not in 1e-06..1e+06"},
      {"500 1e39 319.5 239.5", ":1: fy \"1e39\" is not in 1e-06..1e+06"},
      {"# comment\n500 510 1e20 239.5", ":2: cx \"1e20\" is not in -1e+06..1e+06"},
      {"500 510 319.5 239.5 0 480", ":1: the width \"0\" is not in 1..100000"},
      {"500 510 319.5 239.5 640 1e20", ":1: the height \"1e20\" is not in 1..100000"},
      {"500 510 319.5", ":1: expected 'fx fy cx cy [width height]'"},
      {"500 510 nan 239.5", ":1: expected cx, got \"nan\""},
  };
  for (const auto& [text, expected] : cases) {
    std::ofstream(path) << text << "\n";
    try {
      read_intrinsics(path);
      ADD_FAILURE() << "accepted " << text;
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(path.string() + expected), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

/// A trajectory file without a single pose (only comments, or nothing) is refused, naming the
/// file: read as an empty trajectory it left every frame without a camera, or (for .oni files)
/// with a fixed one, and nothing said so.
TEST(Tum, TrajectoryWithoutPosesIsRefused) {
  const auto dir = ::artrace::test::scratch_path("artrace_empty_trajectory");
  std::filesystem::create_directories(dir);
  const auto path = dir / "poses.txt";
  std::ofstream(path) << "# timestamp tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n";
  EXPECT_EQ(read_tum_trajectory(path).size(), 1u);
  for (const char* text : {"# timestamp tx ty tz qx qy qz qw\n\n", ""}) {
    std::ofstream(path) << text;
    try {
      read_tum_trajectory(path);
      ADD_FAILURE() << "accepted \"" << text << "\"";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(path.string() + ": holds no pose"), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

/// Text inputs are read whole with a text file's checks: a NUL byte is refused with its line and
/// byte (across the reader's 64 KiB chunks too), and so is a file past the size bound; a text file
/// comes back byte for byte.
TEST(TextFile, NulBytesAndOversizedInputsAreRefused) {
  const auto dir = ::artrace::test::scratch_path("artrace_text_file");
  std::filesystem::create_directories(dir);
  const auto path = dir / "t.txt";
  std::string text;
  for (int i = 0; text.size() < 200000; ++i) text += "line " + std::to_string(i) + "\n";
  std::ofstream(path, std::ios::binary) << text;
  EXPECT_EQ(read_text_file(path), text);
  auto error = [](const std::filesystem::path& p, size_t max_bytes) -> std::string {
    try {
      read_text_file(p, max_bytes);
    } catch (const ParseError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(error(path, 199999).find(path.string() + ": runs past 199999 bytes"), std::string::npos);
  EXPECT_EQ(error(path, text.size()), "") << "the bound itself is accepted";
  std::string with_nul = text;
  with_nul[150000] = '\0';
  std::ofstream(path, std::ios::binary) << with_nul;
  const int line = 1 + static_cast<int>(std::count(with_nul.begin(), with_nul.begin() + 150000, '\n'));
  EXPECT_NE(error(path, kMaxTextBytes).find(path.string() + ":" + std::to_string(line) + ": a NUL byte at byte 150000: not a text file"),
            std::string::npos)
      << error(path, kMaxTextBytes);
  EXPECT_NE(error(dir / "missing.txt", kMaxTextBytes).find("missing.txt: cannot open file: No such file or directory"), std::string::npos);
  std::filesystem::remove_all(dir);
}

/// Every text reader given /dev/zero (an endless run of NUL bytes, as a binary file given by
/// mistake begins): refused at once, naming it. Each was read as one endless line until memory ran
/// out. The commands too, under a time limit that a hang would exceed.
TEST(TextFile, EveryTextReaderRefusesDevZero) {
  if (!std::filesystem::exists("/dev/zero")) GTEST_SKIP() << "no /dev/zero on this system";
  const std::filesystem::path zero = "/dev/zero";
  const std::vector<std::pair<const char*, std::function<void()>>> readers = {
      {"trajectory", [&] { read_tum_trajectory(zero); }},
      {"frame list", [&] { read_tum_list(zero); }},
      {"intrinsics.txt", [&] { read_intrinsics(zero); }},
      {"camera file", [&] { read_camera_file(zero); }},
      {"AR scene", [&] { load_ar_scene(zero); }},
      {"AFF scene", [&] { load_aff(zero); }},
  };
  for (const auto& [what, read] : readers) {
    try {
      read();
      ADD_FAILURE() << what << ": read /dev/zero";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find("/dev/zero:1: a NUL byte at byte 0: not a text file"), std::string::npos) << what << ": " << e.what();
    }
  }
#ifdef ARTRACE_BINARY
  if (!std::filesystem::exists(ARTRACE_BINARY)) return;
  const auto log = ::artrace::test::scratch_path("artrace_dev_zero.log");
  const std::string room = (std::filesystem::path(ARTRACE_SOURCE_DIR) / "data/recordings/room").string();
  const std::string demo = (std::filesystem::path(ARTRACE_SOURCE_DIR) / "data/ar/demo.json").string();
  const std::string commands[] = {"export " + room + " --scene " + demo + " --trajectory /dev/zero -o x",
                                  "export " + room + " --scene " + demo + " --intrinsics /dev/zero -o x",
                                  "render /dev/zero -o x.png", "batch /dev/zero", "info /dev/zero"};
  for (const std::string& args : commands) {
    const int status = std::system(("timeout 60 " + std::string(ARTRACE_BINARY) + " " + args + " > " + log.string() + " 2>&1").c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << args << ": status " << status;
    EXPECT_NE(::artrace::test::read_file(log).find("/dev/zero"), std::string::npos) << args << ": " << ::artrace::test::read_file(log);
  }
  std::filesystem::remove(log);
#endif
}

/// Every reader over every broken input: a ParseError naming the file, never a crash.
TEST(BrokenInputs, EveryReaderRefusesEveryBrokenInputWithTheFileNamed) {
  const std::filesystem::path root = std::filesystem::path(ARTRACE_SOURCE_DIR) / "tests/data/broken";
  int checked = 0;
  for (const auto& entry : std::filesystem::directory_iterator(root)) {
    if (entry.path().filename() == "README.md") continue;
    ++checked;
    try {
      auto source = open_recording(entry.path());
      ar::SensorFrame f;
      while (source->next(f)) {
      }
      ADD_FAILURE() << entry.path() << " was read without complaint";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find(entry.path().string()), std::string::npos) << e.what();
    }
  }
  EXPECT_GE(checked, 10);
}

}  // namespace
}  // namespace artrace::io

namespace artrace::io {
namespace {

/// Real TUM sequences, when the shared data holds any (../shared/data/rgbd/<sequence>/).
/// The real fr1/rpy sequence (120 frames): colour paired with depth by the benchmark's rule and
/// poses interpolated at the colour timestamps, against values worked out by an independent
/// script (the associate.py rule, linear translation and slerp over groundtruth.txt).
TEST(Tum, RealFr1RpyAssociationAndPosesAtColourTimes) {
  ARTRACE_REQUIRE_SHARED("rgbd/tum-fr1-rpy/rgb.txt");
  TumReader reader(shared_path.parent_path());
  ASSERT_EQ(reader.frame_count().value(), 120);
  EXPECT_TRUE(reader.warnings().empty());
  EXPECT_DOUBLE_EQ(reader.intrinsics().fx, 517.3) << "Freiburg 1, by the folder's name";
  struct Expected {
    int frame;
    double color_t, depth_t;
    double t[3], q[4];  // translation, quaternion x y z w
  };
  const Expected cases[] = {
      {0, 1305031229.528748, 1305031229.528784, {1.299434, 0.688089, 1.573890}, {0.681736, 0.551023, -0.015106, -0.481021}},
      {59, 1305031231.493669, 1305031231.499244, {1.264395, 0.601647, 1.531367}, {0.612122, 0.661519, -0.429929, -0.053481}},
      {119, 1305031233.493692, 1305031233.500736, {1.280482, 0.621070, 1.523776}, {0.697517, 0.623973, -0.186124, -0.299142}},
  };
  for (const Expected& e : cases) {
    const ar::SensorFrame f = reader.read(e.frame);
    EXPECT_NEAR(f.color_time_s, e.color_t, 1e-6) << "frame " << e.frame;
    EXPECT_NEAR(f.depth_time_s, e.depth_t, 1e-6) << "frame " << e.frame;
    ASSERT_TRUE(f.world_from_camera.has_value()) << "frame " << e.frame;
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(f.world_from_camera->translation()[a], e.t[a], 2e-6) << "frame " << e.frame;
    const Eigen::Quaterniond q(f.world_from_camera->rotation());
    const double sign = q.x() * e.q[0] + q.y() * e.q[1] + q.z() * e.q[2] + q.w() * e.q[3] < 0.0 ? -1.0 : 1.0;
    const double got[4] = {q.x(), q.y(), q.z(), q.w()};
    for (int a = 0; a < 4; ++a) EXPECT_NEAR(sign * got[a], e.q[a], 2e-6) << "frame " << e.frame << ": quaternion component " << a;
  }
}

TEST(Tum, RealSequencesInSharedData) {
  ARTRACE_REQUIRE_SHARED("rgbd");
  int sequences = 0;
  for (const auto& e : std::filesystem::directory_iterator(shared_path)) {
    if (!std::filesystem::exists(e.path() / "rgb.txt")) continue;
    ++sequences;
    TumReader reader(e.path());
    ar::SensorFrame f;
    for (int k = 0; k < 10 && reader.next(f); ++k) {
      EXPECT_EQ(f.color.width, 640);
      EXPECT_EQ(f.depth.height, 480);
      size_t valid = 0;
      for (const float d : f.depth.depth_m) valid += d > 0.2f && d < 10.0f;
      EXPECT_GT(valid, f.depth.depth_m.size() / 4) << e.path();
    }
  }
  if (sequences == 0) GTEST_SKIP() << "no TUM sequence in " << shared_path;
}

}  // namespace
}  // namespace artrace::io
