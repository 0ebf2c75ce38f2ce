// The export command as a user runs it: the clip read back with OpenCV, and no file left behind
// when an export stops early.
#include "../cli_util.h"
#include "../test_util.h"
#include "artrace/io/oni_writer.h"
#include "artrace/io/recording.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <map>

namespace artrace::io {
namespace {

TEST(Export, ClipReadsBackWithTheOverlayWhereTheObjectIs) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export");
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

/// The output's name chooses what is written: a clip for .mp4, .mkv, .mov or .avi in any case
/// (read back with OpenCV); a refusal, naming the extension, for a video or image format that is
/// not written, with nothing left under that name; a folder of PNGs otherwise, with a note when
/// the name has an extension.
TEST(Export, OutputNameChoosesClipFolderOrRefusal) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_names");
  std::filesystem::remove_all(dir);
  const auto scene = box_scene(dir);
  const auto log = dir / "log.txt";
  auto export_to = [&](const std::filesystem::path& out) {
    return run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " +
               scene.string() + " --frames 0:2 --no-shadows -o " + out.string() + " > " + log.string() + " 2>&1");
  };
  const auto upper = dir / "CLIP.AVI";
  ASSERT_EQ(export_to(upper), 0) << ::artrace::test::read_file(log);
  EXPECT_TRUE(std::filesystem::is_regular_file(upper));
  cv::VideoCapture cap(upper.string());
  ASSERT_TRUE(cap.isOpened());
  int frames = 0;
  for (cv::Mat img; cap.read(img);) ++frames;
  EXPECT_EQ(frames, 2);

  for (const char* name : {"clip.webm", "frame.PNG", "anim.gif"}) {
    const auto out = dir / name;
    EXPECT_NE(export_to(out), 0) << name;
    const std::string text = ::artrace::test::read_file(log);
    const std::string ext = std::filesystem::path(name).extension().string();
    EXPECT_NE(text.find(out.string() + ": " + ext + " is not an output format"), std::string::npos) << text;
    EXPECT_FALSE(std::filesystem::exists(out)) << name;
  }

  const auto folder = dir / "frames.v2";
  ASSERT_EQ(export_to(folder), 0);
  EXPECT_NE(::artrace::test::read_file(log).find("note: " + folder.string() + " is not a clip name"), std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(folder / "frame_000000.png"));
  EXPECT_TRUE(std::filesystem::exists(folder / "frame_000001.png"));
  const auto plain = dir / "frames";
  ASSERT_EQ(export_to(plain), 0);
  EXPECT_EQ(::artrace::test::read_file(log).find("is not a clip name"), std::string::npos) << "no note without an extension";
  EXPECT_TRUE(std::filesystem::exists(plain / "frame_000001.png"));
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << e.path();
  }
  std::filesystem::remove_all(dir);
}

/// The other commands' output names: render writes PNG and fuse PLY, whatever the case of the
/// extension, and refuse any other name before any work; convert writes an .oni file for .oni in
/// any case (its header read back), and a TUM folder otherwise, with a note when that folder's
/// name has an extension.
TEST(Cli, OutputNamesChooseTheFormatOrAreRefused) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_cli_output_names");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string room = (kRoot / "data/recordings/room").string(), aff = (kRoot / "data/scenes/room.aff").string();
  const auto log = dir / "log.txt";
  auto artrace = [&](const std::string& args) {
    return run(std::string(ARTRACE_BINARY) + " " + args + " > " + log.string() + " 2>&1");
  };
  const std::pair<std::string, std::string> refused[] = {
      {"render " + aff + " --width 32 --height 24 -o " + (dir / "frame.JPG").string(), "frame.JPG: this command writes PNG images"},
      {"fuse " + room + " -q -o " + (dir / "room.obj").string(), "room.obj: this command writes PLY meshes"},
  };
  for (const auto& [args, message] : refused) {
    EXPECT_NE(artrace(args), 0) << args;
    EXPECT_NE(::artrace::test::read_file(log).find(message), std::string::npos) << ::artrace::test::read_file(log);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "frame.JPG"));
  EXPECT_FALSE(std::filesystem::exists(dir / "room.obj"));

  ASSERT_EQ(artrace("render " + aff + " --width 32 --height 24 -o " + (dir / "FRAME.PNG").string()), 0);
  EXPECT_EQ(::artrace::test::read_file(dir / "FRAME.PNG").substr(1, 3), "PNG");

  ASSERT_EQ(artrace("convert " + room + " -o " + (dir / "REC.ONI").string()), 0) << ::artrace::test::read_file(log);
  ASSERT_TRUE(std::filesystem::is_regular_file(dir / "REC.ONI"));
  EXPECT_EQ(::artrace::test::read_file(dir / "REC.ONI").substr(0, 4), "NI10");
  EXPECT_EQ(::artrace::test::read_file(log).find("note:"), std::string::npos);

  ASSERT_EQ(artrace("convert " + room + " -o " + (dir / "tum.v2").string()), 0);
  EXPECT_NE(::artrace::test::read_file(log).find("note: " + (dir / "tum.v2").string() + " does not end in .oni"),
            std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(dir / "tum.v2" / "rgb.txt"));
  std::filesystem::remove_all(dir);
}

/// An AR scene with the green box 2 m in front of a camera at the world's origin (and the light there).
std::filesystem::path box_ahead_of_origin(const std::filesystem::path& dir) { return box_scene(dir, "[0.0, 0.0, 2.0]", 2.0, "[0, 0, 0]"); }

/// A trajectory that does not cover a frame (here it starts half-way, with samples 0.5 s apart)
/// gives that frame no camera: the frame is exported as recorded, with a warning naming it,
/// instead of with the models placed by a camera at the origin. A frame the trajectory does cover
/// (t = 1.5 s, its first sample: the identity) shows the box standing 2 m in front of it.
TEST(Export, FramesWithoutAPoseAreLeftAsRecordedWithAWarning) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_no_pose");
  std::filesystem::remove_all(dir);
  const auto scene = box_ahead_of_origin(dir);
  const auto poses = dir / "poses.txt";
  std::ofstream(poses) << "1.5 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n";
  const auto room = kRoot / "data/recordings/room";
  const auto log = dir / "log.txt";
  auto export_frame = [&](int k, const std::filesystem::path& out) {
    return run(std::string(ARTRACE_BINARY) + " export " + room.string() + " --scene " + scene.string() + " --trajectory " +
               poses.string() + " --frames " + std::to_string(k) + ":" + std::to_string(k + 1) + " -o " + out.string() +
               " > " + log.string() + " 2>&1");
  };
  auto differing = [](const cv::Mat& a, const cv::Mat& b) {
    cv::Mat diff;
    cv::absdiff(a, b, diff);
    return cv::countNonZero(diff.reshape(1));
  };
  ASSERT_EQ(export_frame(0, dir / "first"), 0) << ::artrace::test::read_file(log);
  const std::string text = ::artrace::test::read_file(log);
  EXPECT_NE(text.find("warning: frame 0 (t = 1.000000 s) has no camera pose: the trajectory runs from 1.500000 to 2.000000 s"),
            std::string::npos) << text;
  EXPECT_NE(text.find("warning: 1 of 1 frames had no camera pose"), std::string::npos) << text;
  const cv::Mat recorded = cv::imread((room / "rgb/1.000000.png").string());
  const cv::Mat exported = cv::imread((dir / "first/frame_000000.png").string());
  ASSERT_FALSE(recorded.empty());
  ASSERT_EQ(exported.size(), recorded.size());
  EXPECT_EQ(differing(exported, recorded), 0) << "the frame as recorded";

  ASSERT_EQ(export_frame(15, dir / "covered"), 0);
  EXPECT_EQ(::artrace::test::read_file(log).find("no camera pose"), std::string::npos);
  const cv::Mat covered = cv::imread((dir / "covered/frame_000015.png").string());
  const cv::Mat covered_recorded = cv::imread((room / "rgb/1.500000.png").string());
  ASSERT_FALSE(covered.empty());
  ASSERT_EQ(covered.size(), covered_recorded.size());
  const cv::Vec3b centre = covered.at<cv::Vec3b>(covered.rows / 2, covered.cols / 2);
  EXPECT_TRUE(centre[1] > 100 && centre[0] < 60 && centre[2] < 60) << "the green box in the middle: " << centre;
  EXPECT_GT(differing(covered, covered_recorded), covered.rows * covered.cols / 20);
  // the benchmark says its figures include frames passed through
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " bench-ar " + room.string() + " --scene " + scene.string() + " --trajectory " +
                poses.string() + " --frames 3 > " + log.string() + " 2>&1"),
            0);
  EXPECT_NE(::artrace::test::read_file(log).find("warning: 3 of 3 frames had no camera pose"), std::string::npos)
      << ::artrace::test::read_file(log);
  std::filesystem::remove_all(dir);
}

/// A TUM folder without groundtruth.txt has no camera poses at all: the export places the models
/// with a fixed camera, the AR scene's world being the camera's frame (as for an .oni file without
/// a trajectory), and says so, naming the recording, instead of doing it silently. The box 2 m in
/// front of that camera stands in the middle of the frame. An empty --trajectory file is refused.
TEST(Export, RecordingWithoutATrajectoryIsCompositedWithAFixedCameraAndAWarning) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_no_trajectory");
  std::filesystem::remove_all(dir);
  const auto scene = box_ahead_of_origin(dir);
  const auto rec = dir / "rec";
  std::filesystem::copy(kRoot / "data/recordings/room", rec, std::filesystem::copy_options::recursive);
  std::filesystem::remove(rec / "groundtruth.txt");
  const auto log = dir / "log.txt";
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + rec.string() + " --scene " + scene.string() + " --frames 0:2 -o " +
                (dir / "out").string() + " > " + log.string() + " 2>&1"),
            0)
      << ::artrace::test::read_file(log);
  const std::string text = ::artrace::test::read_file(log);
  const std::string warning = "warning: " + rec.string() + " has no trajectory: the camera is taken as fixed";
  EXPECT_NE(text.find(warning), std::string::npos) << text;
  EXPECT_EQ(text.find(warning, text.find(warning) + 1), std::string::npos) << "warned once: " << text;
  for (const char* name : {"frame_000000.png", "frame_000001.png"}) {
    const cv::Mat img = cv::imread((dir / "out" / name).string());
    ASSERT_FALSE(img.empty()) << name;
    const cv::Vec3b centre = img.at<cv::Vec3b>(img.rows / 2, img.cols / 2);
    EXPECT_TRUE(centre[1] > 100 && centre[0] < 60 && centre[2] < 60) << name << ": the green box in the middle: " << centre;
  }
  // with the recording's own trajectory: no such warning
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " +
                scene.string() + " --frames 0:1 -o " + (dir / "posed").string() + " > " + log.string() + " 2>&1"),
            0);
  EXPECT_EQ(::artrace::test::read_file(log).find("has no trajectory"), std::string::npos) << ::artrace::test::read_file(log);

  const auto empty = dir / "empty.txt";
  std::ofstream(empty) << "# timestamp tx ty tz qx qy qz qw\n";
  EXPECT_NE(run(std::string(ARTRACE_BINARY) + " export " + rec.string() + " --scene " + scene.string() + " --trajectory " +
                empty.string() + " --frames 0:1 -o " + (dir / "refused").string() + " > " + log.string() + " 2>&1"),
            0);
  EXPECT_NE(::artrace::test::read_file(log).find(empty.string() + ": holds no pose"), std::string::npos)
      << ::artrace::test::read_file(log);
  EXPECT_FALSE(std::filesystem::exists(dir / "refused"));
  std::filesystem::remove_all(dir);
}

/// An anchor on a frame its recording's trajectory gives no pose is refused, naming the scene, the
/// anchor and the frame: the plane found there is in the camera's coordinates, and was taken as
/// the world's, standing the model wherever that put it. On a frame the trajectory covers the
/// anchor stands the model in the picture.
TEST(Export, AnchorOnAFrameWithoutAPoseIsRefused) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_anchor_no_pose");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto poses = dir / "poses.txt";
  std::ofstream(poses) << "1.5 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n";  // frames 15-30 of the room
  const auto room = kRoot / "data/recordings/room";
  const auto log = dir / "log.txt";
  auto anchored_at = [&](int frame) {
    const auto scene = dir / ("anchored_" + std::to_string(frame) + ".json");
    std::ofstream(scene) << R"({ "models": [ { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string()
                         << R"(", "scale": 0.5, "anchor": { "frame": )" << frame << R"(, "pixel": [160, 200] } } ],
                            "lights": [ { "position": [0, -1, 0], "color": [1, 1, 1] } ], "ambient": 1.0 })";
    return run(std::string(ARTRACE_BINARY) + " export " + room.string() + " --scene " + scene.string() + " --trajectory " + poses.string() +
               " --frames 15:16 -q -o " + (dir / ("out_" + std::to_string(frame))).string() + " > " + log.string() + " 2>&1");
  };
  EXPECT_EQ(anchored_at(3), 1);
  EXPECT_NE(::artrace::test::read_file(log).find("anchored_3.json: models[0].anchor.frame: frame 3 (t = 1.100000 s) has no camera pose"),
            std::string::npos)
      << ::artrace::test::read_file(log);
  EXPECT_FALSE(std::filesystem::exists(dir / "out_3"));
  EXPECT_EQ(anchored_at(15), 0) << ::artrace::test::read_file(log);
  std::filesystem::remove_all(dir);
}

/// A trajectory that covers none of the recording's frames (its times on another clock: a motion
/// capture's against the camera's, or one recording's poses given to another) is refused before
/// any work, naming both spans; before, every frame was exported as recorded, without the virtual
/// objects, and the export succeeded with a warning.
TEST(Export, TrajectoryMissingEveryFrameIsRefused) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_far_trajectory");
  std::filesystem::remove_all(dir);
  const auto scene = box_ahead_of_origin(dir);
  const auto far = dir / "far.txt";
  std::ofstream(far) << "100 0 0 0 0 0 0 1\n102 0 0 0 0 0 0 1\n";
  const auto log = dir / "log.txt";
  for (const std::string cmd : {"export", "bench-ar"}) {
    const std::string out = cmd == "export" ? " -o " + (dir / "clip.mp4").string() : " --frames 2";
    EXPECT_EQ(run(std::string(ARTRACE_BINARY) + " " + cmd + " " + (kRoot / "data/recordings/room").string() + " --scene " + scene.string() +
                  " --trajectory " + far.string() + out + " > " + log.string() + " 2>&1"),
              1);
    EXPECT_NE(::artrace::test::read_file(log).find(far.string() + ": its poses run from 100.000000 to 102.000000 s, the frames of " +
                                                  (kRoot / "data/recordings/room").string() + " from 1.000000 to 1.966667 s"),
              std::string::npos)
        << ::artrace::test::read_file(log);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "clip.mp4"));
  std::filesystem::remove_all(dir);
}

/// An export in which no virtual object came into view in any frame (models placed in another
/// frame of reference than the trajectory's world, or behind the camera) ends with a warning
/// saying so, instead of a clip of the recording as it was and no word; one in which they did,
/// without it.
TEST(Export, ModelsNeverInViewAreWarnedAbout) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_out_of_view");
  std::filesystem::remove_all(dir);
  const auto log = dir / "log.txt";
  auto exported = [&](const std::filesystem::path& scene) {
    return run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " + scene.string() +
               " --frames 0:3 -q -o " + (dir / "out").string() + " > " + log.string() + " 2>&1");
  };
  ASSERT_EQ(exported(box_scene(dir / "far", "[100, 100, 100]")), 0) << ::artrace::test::read_file(log);
  EXPECT_NE(::artrace::test::read_file(log).find("warning: no virtual object came into view in any of the 3 frames"), std::string::npos)
      << ::artrace::test::read_file(log);
  ASSERT_EQ(exported(box_scene(dir / "near")), 0) << ::artrace::test::read_file(log);
  EXPECT_EQ(::artrace::test::read_file(log).find("came into view"), std::string::npos) << ::artrace::test::read_file(log);
  std::filesystem::remove_all(dir);
}

/// A clip plays at its recording's rate unless --fps says otherwise: a 10 Hz recording gives a
/// 10 frames/s clip, and its shards record 10 for join (before, every clip was 30 frames/s,
/// playing a 10 Hz recording three times too fast). A conversion to .oni records the same rate.
TEST(Export, ClipsPlayAtTheRecordingsRate) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_rate");
  std::filesystem::remove_all(dir);
  const auto scene = box_scene(dir);
  const auto rec = dir / "rec10";
  {
    const AffScene room = load_aff(kRoot / "data/scenes/room.aff");
    SynthOptions o;
    o.frames = 6;
    o.width = 64;
    o.height = 48;
    o.fps = 10;
    Synthesizer synth(room, o);
    auto w = make_recording_writer(rec);
    synth.write(*w);
  }
  const std::string base = std::string(ARTRACE_BINARY) + " export " + rec.string() + " --scene " + scene.string() + " -q";
  auto rate = [](const std::filesystem::path& clip) { return cv::VideoCapture(clip.string()).get(cv::CAP_PROP_FPS); };
  ASSERT_EQ(run(base + " -o " + (dir / "own.avi").string()), 0);
  EXPECT_NEAR(rate(dir / "own.avi"), 10.0, 1e-6);
  ASSERT_EQ(run(base + " --fps 25 -o " + (dir / "given.avi").string()), 0);
  EXPECT_NEAR(rate(dir / "given.avi"), 25.0, 1e-6);
  ASSERT_EQ(run(base + " --frames 0:3 -o " + (dir / "a").string()), 0);
  ASSERT_EQ(run(base + " --frames 3:6 -o " + (dir / "b").string()), 0);
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " join " + (dir / "a").string() + " " + (dir / "b").string() + " -q -o " +
                (dir / "joined.avi").string()),
            0);
  EXPECT_NEAR(rate(dir / "joined.avi"), 10.0, 1e-6);
  // and a conversion to .oni records the recording's rate in its streams
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " convert " + rec.string() + " -o " + (dir / "rec10.oni").string() + " > /dev/null"), 0);
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " info " + (dir / "rec10.oni").string() + " > " + (dir / "info.txt").string()), 0);
  const std::string info = ::artrace::test::read_file(dir / "info.txt");
  EXPECT_NE(info.find(R"("fps":10,)"), std::string::npos) << info;
  EXPECT_EQ(info.find(R"("fps":30,)"), std::string::npos) << info;
  std::filesystem::remove_all(dir);
}

/// A recording whose depth frames are of another size than its colour frames (an .oni recorded
/// with QVGA depth and VGA colour) is refused by the AR commands, naming it and both sizes: the
/// compositor reads each colour pixel's depth at the same pixel, and without it drew the models
/// over everything, with no shadows on the real surfaces, and said nothing.
TEST(Export, DepthOfAnotherSizeThanTheColourIsRefused) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_depth_size");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto rec = dir / "qvga_depth.oni";
  {
    OniWriter w(rec, {32, 24, 30}, {64, 48, 30});
    const std::vector<uint16_t> depth(32 * 24, 1500);
    const std::vector<uint8_t> rgb(64 * 48 * 3, 128);
    for (int k = 0; k < 3; ++k) w.write(depth.data(), rgb.data(), 33333u * static_cast<uint64_t>(k));
    w.close();
  }
  const auto scene = box_ahead_of_origin(dir);
  const auto log = dir / "log.txt";
  for (const std::string cmd : {"export", "bench-ar"}) {
    const std::string out = cmd == "export" ? " -o " + (dir / "clip.mp4").string() : " --frames 2";
    EXPECT_EQ(run(std::string(ARTRACE_BINARY) + " " + cmd + " " + rec.string() + " --scene " + scene.string() + out + " > " + log.string() + " 2>&1"), 1);
    EXPECT_NE(::artrace::test::read_file(log).find(rec.string() + ": frame 0: depth is 32x24, colour 64x48"), std::string::npos)
        << ::artrace::test::read_file(log);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "clip.mp4"));
  // and by the other commands that need the depth at the colour's pixels, naming the frame
  const std::pair<std::string, std::string> others[] = {
      {"track " + rec.string() + " -o " + (dir / "poses.txt").string(), "frame 0: depth is 32x24, colour 64x48: odometry needs"},
      {"fuse " + rec.string() + " -q -o " + (dir / "room.ply").string(), "frame 0: depth is 32x24, colour 64x48: fusion needs"},
      {"convert " + rec.string() + " -o " + (dir / "tum").string(), (dir / "tum").string() + ": frame 0: depth is 32x24, colour 64x48"},
  };
  for (const auto& [args, message] : others) {
    EXPECT_EQ(run(std::string(ARTRACE_BINARY) + " " + args + " > " + log.string() + " 2>&1"), 1) << args;
    EXPECT_NE(::artrace::test::read_file(log).find(message), std::string::npos) << ::artrace::test::read_file(log);
  }
  for (const char* name : {"poses.txt", "room.ply", "tum", "tum.partial"}) EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " convert " + rec.string() + " -o " + (dir / "copy.oni").string() + " > " + log.string() + " 2>&1"), 0)
      << "an .oni keeps each stream's own size";
  std::filesystem::remove_all(dir);
}

bool is_video(const std::string& name) { return name.find('.') != std::string::npos; }

TEST(Export, StoppedExportLeavesNoFile) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_stop");
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
  // SIGTERM (kill's default; what Slurm sends a job at its time limit, or cancelled, before
  // SIGKILL) and SIGHUP (the terminal closed) stop it the same way: a shard's partial folder and a
  // clip's partial file are removed, and the message names the signal
  const auto log = dir / "log.txt";
  for (const auto& [signal, name] : {std::pair<const char*, const char*>{"TERM", "shard"}, {"TERM", "clip.mp4"}, {"HUP", "hup.avi"}}) {
    const auto out = dir / name;
    // once the first frame is written
    const std::string ready = is_video(name) ? "[ -s " + (dir / (out.stem().string() + ".partial" + out.extension().string())).string() + " ]"
                                             : "[ -e " + (dir / "shard.partial" / "frame_000000.png").string() + " ]";
    const int st = run_until(std::string(ARTRACE_BINARY) + " export " + big.string() + " --scene " + scene.string() + " -o " + out.string() +
                                 " --side-by-side --threads 1 -q",
                             ready, signal, log);
    EXPECT_EQ(st, 1) << signal << " " << name << ": " << ::artrace::test::read_file(log);
    EXPECT_NE(::artrace::test::read_file(log).find("stopped by SIG" + std::string(signal) + ": " + out.string() + " was not written"),
              std::string::npos)
        << ::artrace::test::read_file(log);
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      EXPECT_EQ(e.path().filename().string().rfind(std::filesystem::path(name).stem().string(), 0), std::string::npos)
          << signal << ": " << e.path() << " left behind";
    }
  }
  std::filesystem::remove_all(dir);
}

/// Two exports to one output at once (two shards given the same folder by mistake, the same
/// command started in two terminals): the second is refused, naming the output, while the first
/// runs, and the first's output is whole and its own. Before, the second removed the first's
/// partial output and wrote its own frames among the first's. A conversion to the same .oni or
/// TUM folder as one running is refused the same way.
TEST(Export, SecondWriterOfTheSameOutputIsRefused) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_two_writers");
  std::filesystem::remove_all(dir);
  const auto scene = box_scene(dir);
  const auto big = dir / "big";
  synth_room(big, 120, 320, 240);
  const std::string bin = ARTRACE_BINARY, room = (kRoot / "data/recordings/room").string();
  struct Case {
    std::string first, second, output, partial;
  };
  const Case cases[] = {
      {"export " + big.string() + " --scene " + scene.string() + " --side-by-side --threads 1 -q",
       "export " + room + " --scene " + scene.string() + " -q", "frames", "frames.partial"},
      {"export " + big.string() + " --scene " + scene.string() + " --side-by-side --threads 1 -q",
       "export " + room + " --scene " + scene.string() + " -q", "clip.avi", "clip.partial.avi"},
      {"convert " + big.string(), "convert " + room, "tum", "tum.partial"},
  };
  for (const Case& c : cases) {
    const auto out = dir / c.output;
    // the first in the background, held (SIGSTOP) once its partial output is there while the
    // second runs, then let go
    const std::string script = bin + " " + c.first + " -o " + out.string() + " > " + (dir / "first.log").string() + " 2>&1 & first=$!; " +
                               "for i in $(seq 3000); do [ -e " + (dir / c.partial).string() + " ] && break; sleep 0.01; done; kill -STOP $first; " +
                               bin + " " + c.second + " -o " + out.string() + " > " + (dir / "second.log").string() + " 2>&1; echo $? > " +
                               (dir / "second.rc").string() + "; kill -CONT $first; wait $first";
    EXPECT_EQ(run("bash -c '" + script + "'"), 0) << c.first << ": " << ::artrace::test::read_file(dir / "first.log");
    EXPECT_EQ(::artrace::test::read_file(dir / "second.rc"), "1\n") << ::artrace::test::read_file(dir / "second.log");
    EXPECT_NE(::artrace::test::read_file(dir / "second.log").find(out.string() + ": is being written by another process"), std::string::npos)
        << ::artrace::test::read_file(dir / "second.log");
  }
  // the first's outputs, whole: 120 frames of the big recording, side by side
  int frames = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir / "frames")) frames += e.path().extension() == ".png";
  EXPECT_EQ(frames, 120);
  EXPECT_EQ(cv::imread((dir / "frames" / "frame_000119.png").string()).cols, 3 * 320);
  cv::VideoCapture clip((dir / "clip.avi").string());
  EXPECT_EQ(static_cast<int>(clip.get(cv::CAP_PROP_FRAME_COUNT)), 120);
  EXPECT_EQ(open_recording(dir / "tum")->frame_count(), 120);
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << e.path() << " left behind";
  }
  std::filesystem::remove_all(dir);
}

/// Numeric options out of their range, NaN and infinities included (CLI11's own range check lets
/// NaN through, and an export with --fps nan then failed inside OpenCV with a misleading message):
/// refused before any work, naming the option.
TEST(Cli, OutOfRangeOptionsAreRefusedByName) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_cli_ranges");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string room = (kRoot / "data/recordings/room").string(), aff = (kRoot / "data/scenes/room.aff").string();
  const std::string scene = (kRoot / "data/ar/demo.json").string(), out = (dir / "out").string();
  const std::pair<std::string, std::string> cases[] = {
      {"render " + aff + " --time nan -o " + out + ".png", "--time"},
      {"render " + aff + " --time inf -o " + out + ".png", "--time"},
      {"render " + aff + " --frame -3 -o " + out + ".png", "--frame"},
      {"render " + aff + " --threads -2 -o " + out + ".png", "--threads"},
      {"export " + room + " --scene " + scene + " -o " + out + ".avi --fps nan", "--fps"},
      {"export " + room + " --scene " + scene + " -o " + out + " --first -1", "--first"},
      {"replay " + room + " --scene " + scene + " --speed nan", "--speed"},
      {"synth --scene " + aff + " -o " + out + " --fov 0", "--fov"},
      {"synth --scene " + aff + " -o " + out + " --orbit nan", "--orbit"},
      {"bench-bart --scene " + aff + " --min-weight nan", "--min-weight"},
      {"bench-core --scene " + aff + " --sah-intersection 0", "--sah-intersection"},
      {"bench-occlusion --scene " + aff + " --box-min 0 nan 0", "--box-min"},
      {"track " + room + " -o " + out + ".txt --frames -1", "--frames"},
  };
  const auto log = dir / "log.txt";
  for (const auto& [args, option] : cases) {
    EXPECT_NE(run(std::string(ARTRACE_BINARY) + " " + args + " > " + log.string() + " 2>&1"), 0) << args;
    const std::string text = ::artrace::test::read_file(log);
    EXPECT_NE(text.find(option + ": Value"), std::string::npos) << args << "\n" << text;
    EXPECT_NE(text.find("not in range"), std::string::npos) << args << "\n" << text;
  }
  EXPECT_FALSE(std::filesystem::exists(out)) << "nothing was written";
  EXPECT_FALSE(std::filesystem::exists(out + ".png"));
  std::filesystem::remove_all(dir);
}

/// An export gives the same frames for any thread count: the demo scene (a node-animated box, a
/// glass sphere, a mirror, a skinned tube, shadows on the real surfaces) exported as PNGs with 1
/// and 2 threads, compared byte for byte.
TEST(Export, SameFramesForAnyThreadCount) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_threads");
  std::filesystem::remove_all(dir);
  std::vector<std::string> frames[2];
  for (const int threads : {1, 2}) {
    const auto out = dir / ("t" + std::to_string(threads));
    ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " +
                  (kRoot / "data/ar/demo.json").string() + " -o " + out.string() + " --last 5 --threads " +
                  std::to_string(threads) + " -q > /dev/null"),
              0);
    frames[threads - 1] = ::artrace::test::read_pngs(out);
  }
  ASSERT_EQ(frames[0].size(), 6u);
  ASSERT_EQ(frames[1].size(), 6u);
  for (size_t k = 0; k < 6; ++k) EXPECT_TRUE(frames[0][k] == frames[1][k]) << "frame " << k;
  std::filesystem::remove_all(dir);
}

/// The export lines the depth up with the colour by itself: the bundled recording was made with the
/// Kinect-like depth model, whose depth sits one pixel right of the colour. --depth-shift auto gives
/// frames byte-identical to --depth-shift 1,0 and different from 0,0 (the depth as read), and says
/// what it found.
TEST(Export, DepthShiftAutoIsTheRecordingsOwnShift) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_export_depth_shift");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::map<std::string, std::vector<std::string>> frames;
  for (const std::string shift : {"auto", "1,0", "0,0"}) {
    const auto out = dir / (shift == "auto" ? "auto" : shift == "1,0" ? "one" : "none");
    ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + (kRoot / "data/recordings/room").string() + " --scene " +
                  (kRoot / "data/ar/demo.json").string() + " -o " + out.string() + " --first 10 --last 12 --depth-shift " + shift +
                  " > /dev/null 2> " + out.string() + ".log"),
              0);
    for (int k = 10; k <= 12; ++k) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%06d.png", k);
      ASSERT_TRUE(std::filesystem::exists(out / name)) << (out / name);
      frames[shift].push_back(::artrace::test::read_file(out / name));
    }
  }
  const std::string text = ::artrace::test::read_file(dir / "auto.log");
  EXPECT_NE(text.find("note: depth shift +1,+0 px"), std::string::npos) << text;
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_TRUE(frames["auto"][k] == frames["1,0"][k]) << "frame " << k;
    EXPECT_FALSE(frames["auto"][k] == frames["0,0"][k]) << "frame " << k;
  }
  std::filesystem::remove_all(dir);
}

/// track lines the depth up with the colour as export does: on the bundled recording (its depth
/// one pixel right of the colour) --depth-shift auto finds +1,+0 and gives the trajectory of
/// --depth-shift 1,0, which follows the recording's own poses more closely than the depth as read.
TEST(Track, DepthShiftAutoLinesTheDepthUpAndTracksCloser) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_track_depth_shift");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::map<std::string, nlohmann::json> drift;
  std::map<std::string, std::string> poses;
  for (const std::string shift : {"auto", "1,0", "0,0"}) {
    const auto out = dir / (shift == "auto" ? "auto" : shift == "1,0" ? "one" : "none");
    ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " track " + (kRoot / "data/recordings/room").string() + " -o " +
                  out.string() + ".txt --json " + out.string() + ".json --depth-shift " + shift + " > /dev/null 2> " +
                  out.string() + ".log"),
              0);
    drift[shift] = nlohmann::json::parse(std::ifstream(out.string() + ".json")).at("drift");
    poses[shift] = ::artrace::test::read_file(out.string() + ".txt");
  }
  const std::string text = ::artrace::test::read_file(dir / "auto.log");
  EXPECT_NE(text.find("note: depth shift +1,+0 px"), std::string::npos) << text;
  ASSERT_FALSE(poses["auto"].empty());
  EXPECT_EQ(poses["auto"], poses["1,0"]);
  EXPECT_NE(poses["auto"], poses["0,0"]);
  EXPECT_LT(drift["auto"].at("rms_m").get<double>(), drift["0,0"].at("rms_m").get<double>());
  EXPECT_LT(drift["auto"].at("final_m").get<double>(), drift["0,0"].at("final_m").get<double>());
  std::filesystem::remove_all(dir);
}

/// A real Kinect recording (OpenNI 1.x, 16zT depth, JPEG colour) through the whole AR path: a green
/// box 0.6 m in front of the fixed camera (the camera frame: y down, z forward), nearer than the
/// desk and the person, is drawn at the centre of every frame.
TEST(Export, RealOniRecordingThroughTheArPath) {
  ARTRACE_REQUIRE_BINARY();
  ARTRACE_REQUIRE_SHARED("rgbd/oni-kinect1-tabletop-4f/Captured.oni");
  const auto dir = ::artrace::test::scratch_path("artrace_export_oni");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto scene = dir / "scene.json";
  std::ofstream(scene) << R"({ "models": [ { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string()
                       << R"(", "position": [0.0, 0.0, 0.6], "scale": 0.5,
                            "material": { "kind": "diffuse", "base_color": [0.0, 1.0, 0.0] } } ],
                          "lights": [ { "position": [0, -1, 0], "color": [1, 1, 1] } ], "ambient": 1.0 })";
  const auto out = dir / "frames";
  ASSERT_EQ(run(std::string(ARTRACE_BINARY) + " export " + shared_path.string() + " --scene " + scene.string() + " -o " + out.string() +
                " -q > /dev/null"),
            0);
  int frames = 0;
  for (const auto& e : std::filesystem::directory_iterator(out)) {
    if (e.path().extension() != ".png") continue;  // and shard.json
    const cv::Mat img = cv::imread(e.path().string());
    ASSERT_EQ(img.cols, 640);
    const cv::Vec3b c = img.at<cv::Vec3b>(240, 320);  // BGR
    EXPECT_TRUE(c[1] > 150 && c[0] < 80 && c[2] < 80) << e.path() << ": " << c;
    ++frames;
  }
  EXPECT_EQ(frames, 4);
  std::filesystem::remove_all(dir);
}

/// bench-core against its Embree reference, as docs/benchmarks.md runs it: it completes (Embree's
/// 8- and 16-wide calls fault on a valid mask not aligned as the packet), and Embree's camera-ray
/// hits and shadow answers agree with ours, where they differ brute force finding none of ours
/// wrong. In its default mode and, with --embree-robust, in its robust mode, each as Embree
/// itself reports the scenes' flags.
TEST(BenchCore, EmbreeReferenceRunsAndAgreesWithTheCore) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_bench_core_embree");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  {  // robust mode without the reference is refused by name, not ignored
    const auto log = dir / "refused.txt";
    EXPECT_NE(run(std::string(ARTRACE_BINARY) + " bench-core --scene " + (kRoot / "data/scenes/room.aff").string() +
                  " --width 8 --height 8 --runs 1 --embree-robust > " + log.string() + " 2>&1"),
              0);
    const std::string text = ::artrace::test::read_file(log);
    EXPECT_NE(text.find("--embree-robust needs --reference embree"), std::string::npos) << text;
  }
  constexpr int kRobustFlag = 1 << 2;  // RTC_SCENE_FLAG_ROBUST in Embree 3's rtcore_scene.h
  const struct {
    int lanes;
    bool robust;
  } runs[] = {{8, false}, {16, false}, {16, true}};
  for (const auto& [lanes, robust] : runs) {
    const auto json = dir / ("lanes" + std::to_string(lanes) + (robust ? "_robust" : "") + ".json");
    const auto log = dir / "log.txt";
    const int rc = run(std::string(ARTRACE_BINARY) + " bench-core --scene " + (kRoot / "data/scenes/room.aff").string() +
                       " --width 96 --height 64 --runs 1 --threads 2 --verify-rays 100 --lanes " + std::to_string(lanes) +
                       " --reference embree" + (robust ? " --embree-robust" : "") + " --json " + json.string() + " > " +
                       log.string() + " 2>&1");
    const std::string text = ::artrace::test::read_file(log);
    if (rc != 0 && text.find("this build has no Embree") != std::string::npos) GTEST_SKIP() << "built without Embree";
    ASSERT_EQ(rc, 0) << text;
    const nlohmann::json out = nlohmann::json::parse(std::ifstream(json));
    const nlohmann::json& e = out.at("embree");
    EXPECT_EQ(e.at("robust").get<bool>(), robust);
    for (const char* q : {"HIGH", "MEDIUM"})
      EXPECT_EQ(e.at("scene_flags").at(q).get<int>() & kRobustFlag, robust ? kRobustFlag : 0) << q;
    EXPECT_GE(e.at("primary_agreement").get<double>(), 0.999) << "lanes " << lanes;
    EXPECT_EQ(e.at("shadow_disagreeing_lanes_wrong").at("artrace").get<size_t>(), 0u) << "lanes " << lanes;
    // and the reference answers its shadow rays too (Embree's test is not watertight: a few lanes
    // on edges may differ, not more)
    EXPECT_LE(e.at("shadow_disagreeing_lanes_wrong").at("embree").get<size_t>() * 1000,
              out.at("ray_counts").at("shadow").get<size_t>())
        << "lanes " << lanes;
    for (const char* key : {"primary_single", "primary_packet_4", "primary_packet_8", "primary_packet_16", "shadow", "incoherent"})
      EXPECT_GT(e.at("rays").at(key).get<double>(), 0.0) << key;
    // ours: camera packets as the two-level scene traces them, and the kd-tree's alone, each
    // checked against the kd-tree's hits (wide BVH packets included) before timing
    EXPECT_GT(out.at("rays").at("primary_packet").get<double>(), 0.0);
    EXPECT_GT(out.at("rays").at("primary_packet_kdtree").get<double>(), 0.0);
    EXPECT_GT(e.at("paired_ratio").at("primary_packet_kdtree").get<double>(), 0.0);
    EXPECT_EQ(out.at("verify").at("wide_bvh_vs_kdtree_mismatches").get<size_t>(), 0u);
    // every kind of ray through both of Embree's BVHs, the faster one's rate the one compared
    EXPECT_GT(e.at("build_ms").get<double>(), 0.0);
    EXPECT_GT(e.at("build_ms_medium").get<double>(), 0.0);
    for (const char* key : {"primary_single", "primary_packet_4", "primary_packet_8", "primary_packet_16",
                            "shadow_incoherent_flag", "shadow_coherent_flag", "incoherent"}) {
      const double high = e.at("rays").at(std::string(key) + "_HIGH").get<double>();
      const double medium = e.at("rays").at(std::string(key) + "_MEDIUM").get<double>();
      EXPECT_GT(high, 0.0) << key;
      EXPECT_GT(medium, 0.0) << key;
      EXPECT_EQ(e.at("rays").at(key).get<double>(), std::max(high, medium)) << key;
      EXPECT_EQ(e.at("quality").at(key).get<std::string>(), high >= medium ? "HIGH" : "MEDIUM") << key;
    }
    const nlohmann::json& r = e.at("rays");
    EXPECT_EQ(r.at("primary_packet").get<double>(),
              std::max({r.at("primary_packet_4").get<double>(), r.at("primary_packet_8").get<double>(),
                        r.at("primary_packet_16").get<double>()}));
    EXPECT_EQ(r.at("shadow").get<double>(),
              std::max(r.at("shadow_incoherent_flag").get<double>(), r.at("shadow_coherent_flag").get<double>()));
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
