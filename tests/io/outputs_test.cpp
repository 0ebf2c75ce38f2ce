// What a command may replace when it writes its output. A folder output (export's and join's
// frames, convert's TUM layout) replaces what is under its name, so these tests hold the commands
// to replacing only what they wrote themselves, and never an input.
#include "../cli_util.h"
#include "../test_util.h"

#include <gtest/gtest.h>

#include <fstream>
#include <map>

namespace artrace::io {
namespace {

/// Every regular file under `dir` with its bytes, for telling whether anything in it changed.
std::map<std::string, std::string> snapshot(const std::filesystem::path& dir) {
  std::map<std::string, std::string> files;
  if (std::filesystem::is_regular_file(dir)) {
    files[dir.filename().string()] = ::artrace::test::read_file(dir);
    return files;
  }
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files[std::filesystem::relative(e.path(), dir).string()] = ::artrace::test::read_file(e.path());
  }
  return files;
}

/// Each command is refused, before any work and naming the path and why, when its output would
/// replace one of its inputs (the recording, the scene, a shard), a folder holding an input, a
/// file or folder an input recording's reader reads (its lists, trajectory, intrinsics, images), a
/// folder of files the command did not write,
/// a file where a folder goes or a folder where a file goes, or its own other output. What was
/// there is left as it was. The outputs a command did write before (a folder of frames, a TUM
/// folder, a clip) are replaced as before.
TEST(Cli, OutputsNeverReplaceInputsOrFoldersOfOtherFiles) {
  ARTRACE_REQUIRE_BINARY();
  const auto dir = ::artrace::test::scratch_path("artrace_cli_outputs");
  std::filesystem::remove_all(dir);
  const auto rec = dir / "work" / "rec";
  std::filesystem::create_directories(rec.parent_path());
  std::filesystem::copy(kRoot / "data/recordings/room", rec, std::filesystem::copy_options::recursive);
  const auto scene = box_scene(dir / "scene");
  std::filesystem::create_directories(dir / "docs");
  std::ofstream(dir / "docs" / "thesis.txt") << "four years\n";
  std::ofstream(dir / "notes.txt") << "not a folder\n";
  std::filesystem::create_directories(dir / "folder.mp4");
  std::ofstream(dir / "folder.mp4" / "keep.txt") << "a folder named like a clip\n";
  const auto log = dir / "log.txt";
  auto artrace = [&](const std::string& args) {
    return run(std::string(ARTRACE_BINARY) + " " + args + " > " + log.string() + " 2>&1");
  };
  const std::string r = rec.string(), s = " --scene " + scene.string() + " -q --frames 0:2";
  // two shards to join
  ASSERT_EQ(artrace("export " + r + " --scene " + scene.string() + " -q --frames 0:1 -o " + (dir / "a").string()), 0)
      << ::artrace::test::read_file(log);
  ASSERT_EQ(artrace("export " + r + " --scene " + scene.string() + " -q --frames 1:30 -o " + (dir / "b").string()), 0);
  const std::filesystem::path kept[] = {rec, scene, dir / "docs", dir / "notes.txt", dir / "folder.mp4", dir / "a", dir / "b"};
  std::vector<std::map<std::string, std::string>> before;
  for (const auto& p : kept) before.push_back(snapshot(p));

  const std::pair<std::string, std::string> refused[] = {
      {"export " + r + s + " -o " + r, r + ": is the input " + r},
      {"export " + r + s + " -o " + (dir / "work").string(), (dir / "work").string() + ": holds the input " + r},
      {"export " + r + s + " -o " + (rec / "rgb").string(), (rec / "rgb").string() + ": lies inside the input " + r},
      {"export " + r + s + " -o " + (dir / "docs").string(), (dir / "docs").string() + ": holds thesis.txt, which this command did not write"},
      {"export " + r + s + " -o " + (dir / "notes.txt").string(), (dir / "notes.txt").string() + ": is a file, not a folder"},
      {"export " + r + s + " -o " + (dir / "folder.mp4").string(), (dir / "folder.mp4").string() + ": is a folder, not a file"},
      {"export " + r + s + " -o " + scene.string(), scene.string() + ": is the input " + scene.string()},
      {"convert " + r + " -o " + r, r + ": is the input " + r},
      {"convert " + r + " -o " + (dir / "docs").string(), (dir / "docs").string() + ": holds thesis.txt, which this command did not write"},
      {"convert " + r + " -o " + (dir / "a").string(), (dir / "a").string() + ": holds frame_000000.png, which this command did not write"},
      {"track " + r + " -o " + (rec / "groundtruth.txt").string(), (rec / "groundtruth.txt").string() + ": lies inside the input " + r},
      {"track " + r + " -o " + (dir / "t.txt").string() + " --json " + (dir / "t.txt").string(),
       (dir / "t.txt").string() + ": named as two outputs"},
      {"fuse " + r + " -q -o " + (dir / "room.ply").string() + " --json " + (rec / "rgb.txt").string(),
       (rec / "rgb.txt").string() + ": lies inside the input " + r},
      {"join " + (dir / "a").string() + " " + (dir / "b").string() + " -q -o " + (dir / "a").string(),
       (dir / "a").string() + ": is the input " + (dir / "a").string()},
      {"bench-ar " + r + " --scene " + scene.string() + " --frames 2 --json " + scene.string(), scene.string() + ": is the input"},
      {"info " + scene.string() + " --json " + scene.string(), scene.string() + ": is the input"},
  };
  for (const auto& [args, message] : refused) {
    EXPECT_NE(artrace(args), 0) << args;
    EXPECT_NE(::artrace::test::read_file(log).find(message), std::string::npos) << args << "\n" << ::artrace::test::read_file(log);
  }
  for (size_t i = 0; i < std::size(kept); ++i) EXPECT_EQ(snapshot(kept[i]), before[i]) << kept[i];
  EXPECT_FALSE(std::filesystem::exists(dir / "room.ply"));
  EXPECT_FALSE(std::filesystem::exists(dir / "t.txt"));

  // what the commands wrote themselves they replace
  std::filesystem::remove(dir / "a" / "frame_000000.png");
  ASSERT_EQ(artrace("export " + r + " --scene " + scene.string() + " -q --frames 0:1 -o " + (dir / "a").string()), 0)
      << ::artrace::test::read_file(log);
  EXPECT_TRUE(std::filesystem::exists(dir / "a" / "frame_000000.png"));
  ASSERT_EQ(artrace("join " + (dir / "a").string() + " " + (dir / "b").string() + " -q -o " + (dir / "c").string()), 0)
      << ::artrace::test::read_file(log);
  ASSERT_EQ(artrace("join " + (dir / "a").string() + " " + (dir / "b").string() + " -q -o " + (dir / "c").string()), 0);
  ASSERT_EQ(artrace("convert " + r + " -o " + (dir / "tum").string()), 0) << ::artrace::test::read_file(log);
  ASSERT_EQ(artrace("convert " + (dir / "tum").string() + " -o " + (dir / "tum2").string()), 0);
  ASSERT_EQ(artrace("convert " + (dir / "tum2").string() + " -o " + (dir / "tum").string()), 0) << ::artrace::test::read_file(log);
  ASSERT_EQ(artrace("export " + r + s + " -o " + (dir / "clip.mp4").string()), 0);
  ASSERT_EQ(artrace("export " + r + s + " -o " + (dir / "clip.mp4").string()), 0) << ::artrace::test::read_file(log);
  std::filesystem::create_directories(dir / "empty");
  ASSERT_EQ(artrace("export " + r + s + " -o " + (dir / "empty").string()), 0) << ::artrace::test::read_file(log);
  EXPECT_TRUE(std::filesystem::exists(dir / "empty" / "shard.json"));
  // an output inside the recording's folder under a name no reader reads is fine, new or not
  ASSERT_EQ(artrace("track " + r + " --frames 3 -o " + (rec / "estimated.txt").string()), 0) << ::artrace::test::read_file(log);
  ASSERT_EQ(artrace("track " + r + " --frames 3 -o " + (rec / "estimated.txt").string()), 0) << ::artrace::test::read_file(log);
  // but not a name its reader would read (a camera file), although nothing has it yet
  EXPECT_NE(artrace("track " + r + " --frames 3 -o " + (rec / "camera.yaml").string()), 0);
  EXPECT_NE(::artrace::test::read_file(log).find("lies inside the input " + r), std::string::npos);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
