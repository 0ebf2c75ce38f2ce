// Files written whole or not at all, on a full disk too. /dev/full stands for the full disk: every
// write that reaches it fails with ENOSPC, as a real full disk fails a flush or a close. Writers
// meet it through a link to it standing where their ".partial" file goes; before, a stream's
// unchecked flush (and OpenCV's imwrite, tinygltf and Open3D's PLY writer, which report success)
// left an empty or cut file under the final name, and the command succeeded.
#include "artrace/io/atomic_file.h"
#include "artrace/io/fusion.h"
#include "artrace/io/gltf_model.h"
#include "artrace/io/tum_reader.h"

#include "../cli_util.h"
#include "../test_util.h"

#include <sys/stat.h>

#include <fstream>
#include <stdexcept>

namespace artrace::io {
namespace {

#define ARTRACE_REQUIRE_DEV_FULL()                                                      \
  if (!std::filesystem::exists("/dev/full")) {                                          \
    GTEST_SKIP() << "no /dev/full on this system: a full disk cannot be stood in for";  \
  }

/// The next atomic write of `path` meets a full disk: PATH.partial is a link to /dev/full.
void full_disk_for(const std::filesystem::path& path) {
  std::filesystem::create_directories(path.parent_path());
  std::filesystem::create_symlink("/dev/full", path.string() + ".partial");
}

bool nothing_at(const std::filesystem::path& p) {
  return std::filesystem::symlink_status(p).type() == std::filesystem::file_type::not_found;
}

/// `f()` throws a std::runtime_error whose message holds `expected`.
template <class F>
::testing::AssertionResult throws_with(const F& f, const std::string& expected) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).find(expected) != std::string::npos) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "threw \"" << e.what() << "\", not \"" << expected << "\"";
  }
  return ::testing::AssertionFailure() << "did not throw";
}

TEST(AtomicFile, WrittenWholeOrNotAtAllAndTheFullDiskNamed) {
  ARTRACE_REQUIRE_DEV_FULL();
  const auto dir = ::artrace::test::scratch_path("artrace_atomic_file");
  std::filesystem::remove_all(dir);
  const auto a = dir / "sub" / "a.txt";
  write_file_atomically(a, "first\n");
  EXPECT_EQ(::artrace::test::read_file(a), "first\n");
  EXPECT_TRUE(nothing_at(a.string() + ".partial"));
  // a failed write leaves the earlier file as it was, and no .partial
  full_disk_for(a);
  EXPECT_TRUE(throws_with([&] { write_file_atomically(a, "second\n"); }, a.string() + ": cannot write: No space left on device"));
  EXPECT_EQ(::artrace::test::read_file(a), "first\n");
  EXPECT_TRUE(nothing_at(a.string() + ".partial"));
  // a few bytes (all in the buffer until the flush) and many
  for (const size_t size : {size_t{5}, size_t{1} << 20}) {
    const auto b = dir / ("b" + std::to_string(size));
    full_disk_for(b);
    EXPECT_TRUE(throws_with([&] { write_file_atomically(b, std::string(size, 'x')); }, "No space left on device")) << size;
    EXPECT_TRUE(nothing_at(b)) << size;
    EXPECT_TRUE(nothing_at(b.string() + ".partial")) << size;
  }
  // written in place: the device named, and left where it is
  EXPECT_TRUE(throws_with([] { write_file("/dev/full", "abc"); }, "/dev/full: cannot write: No space left on device"));
  EXPECT_TRUE(std::filesystem::exists("/dev/full"));
  EXPECT_TRUE(throws_with([&] { write_file(dir / "no" / "such" / "folder", "abc"); }, "cannot write: No such file or directory"));
  // a folder where the file should go: refused, and the .partial gone
  std::filesystem::create_directories(dir / "taken" / "inside");
  EXPECT_TRUE(throws_with([&] { write_file_atomically(dir / "taken", "abc"); }, (dir / "taken").string() + ": cannot write: "));
  EXPECT_TRUE(nothing_at(dir.string() + "/taken.partial"));
  EXPECT_TRUE(std::filesystem::is_directory(dir / "taken" / "inside"));
  std::filesystem::remove_all(dir);
}

/// The library's writers on a full disk: the trajectory, a glTF model (text and binary) and the
/// fused room's PLY each fail naming their file, and leave nothing under its name.
TEST(AtomicFile, EveryWriterReportsAFullDisk) {
  ARTRACE_REQUIRE_DEV_FULL();
  const auto dir = ::artrace::test::scratch_path("artrace_atomic_writers");
  std::filesystem::remove_all(dir);
  const auto trajectory = dir / "poses.txt";
  full_disk_for(trajectory);
  const ar::PoseSample still{1.0, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity()};
  EXPECT_TRUE(throws_with([&] { write_tum_trajectory(trajectory, ar::Trajectory({still})); },
                          trajectory.string() + ": cannot write: No space left on device"));
  for (const char* name : {"box.gltf", "box.glb"}) {
    const auto model = dir / name;
    full_disk_for(model);
    EXPECT_TRUE(throws_with([&] { write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), model); },
                            model.string() + ": cannot write: No space left on device"));
    EXPECT_TRUE(nothing_at(model)) << name;
    // and with room on the disk, the model reads back
    std::filesystem::remove(model.string() + ".partial");
    write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), model);
    EXPECT_FALSE(load_gltf(model).meshes.empty()) << name;
  }
  ar::RoomMesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.colours = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  mesh.triangles = {{0, 1, 2}};
  const auto ply = dir / "room.ply";
  full_disk_for(ply);
  EXPECT_TRUE(throws_with([&] { write_room_ply(mesh, ply); }, ply.string() + ": cannot write: No space left on device"));
  EXPECT_TRUE(nothing_at(ply));
  EXPECT_TRUE(nothing_at(trajectory));
  std::filesystem::remove_all(dir);
}

/// A partial output is held by one writer at a time: a second claim of it, made while the first
/// lives, is refused naming the output (flock locks belong to an open file, so a second claim in
/// the same process meets the first as another process's would); once the first is gone, its
/// partial (as a process that died leaves it, contents and all) is removed and claimed afresh,
/// empty. Files and folders alike; nothing but the partial itself is left beside it.
TEST(AtomicFile, PartialOutputIsHeldByOneWriterAtATime) {
  const auto dir = ::artrace::test::scratch_path("artrace_partial_claims");
  std::filesystem::remove_all(dir);
  for (const auto kind : {PartialOutput::Kind::folder, PartialOutput::Kind::file}) {
    const bool folder = kind == PartialOutput::Kind::folder;
    const auto partial = dir / (folder ? "frames.partial" : "clip.partial.mp4");
    {
      const mode_t mask = ::umask(022);
      PartialOutput first(partial, kind, "OUT");
      ::umask(mask);
      EXPECT_EQ(first.path(), partial);
      EXPECT_EQ(folder, std::filesystem::is_directory(partial));
      // the permissions a file or folder made by open() or mkdir() would have (mkstemp's and
      // mkdtemp's own are the owner's alone: an export's clip unreadable by anyone else)
      struct stat st {};
      ASSERT_EQ(::stat(partial.c_str(), &st), 0);
      EXPECT_EQ(st.st_mode & 0777, folder ? 0755u : 0644u);
      if (folder) std::ofstream(partial / "frame_000000.png") << "written";
      else std::ofstream(partial) << "written";
      EXPECT_TRUE(throws_with([&] { PartialOutput second(partial, kind, "OUT"); },
                              "OUT: is being written by another process (" + partial.string() + " is in use)"));
      EXPECT_TRUE(folder ? std::filesystem::exists(partial / "frame_000000.png") : std::filesystem::file_size(partial) == 7)
          << "the first writer's partial is left alone";
    }
    PartialOutput again(partial, kind, "OUT");
    EXPECT_TRUE(folder ? std::filesystem::is_empty(partial) : std::filesystem::file_size(partial) == 0) << "claimed afresh";
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
    EXPECT_EQ(names, std::vector<std::string>{partial.filename().string()});
    std::filesystem::remove_all(partial);
  }
  std::filesystem::remove_all(dir);
}

/// The commands on a full disk: each fails, naming its output and the reason, and leaves nothing
/// under the output's name (a report, a trajectory, a model, an image, a mesh).
TEST(AtomicFile, CommandsReportAFullDisk) {
  ARTRACE_REQUIRE_BINARY();
  ARTRACE_REQUIRE_DEV_FULL();
  const auto dir = ::artrace::test::scratch_path("artrace_atomic_commands");
  std::filesystem::remove_all(dir);
  const std::string room = (kRoot / "data/recordings/room").string();
  const std::string bin = ARTRACE_BINARY;
  const auto out = [&](const char* name) { return dir / name; };
  const std::pair<std::string, std::filesystem::path> commands[] = {  // a command, and the output it writes
      {"info " + room + " --json " + out("info.json").string(), out("info.json")},
      {"track " + room + " --frames 3 -o " + out("poses.txt").string(), out("poses.txt")},
      {"bench-ar " + room + " --scene " + (kRoot / "data/ar/demo.json").string() + " --frames 2 --json " + out("bench.json").string(),
       out("bench.json")},
      {"render " + (kRoot / "data/scenes/room.aff").string() + " --width 32 --height 24 -o " + out("frame.png").string(), out("frame.png")},
      {"make-models " + out("models").string(), out("models") / "spinning_box.gltf"},
      {"fuse " + room + " --every 10 -q -o " + out("room.ply").string(), out("room.ply")},
  };
  const auto log = dir / "log.txt";
  for (const auto& [command, written] : commands) {
    full_disk_for(written);
    EXPECT_NE(run(bin + " " + command + " > " + log.string() + " 2>&1"), 0) << command;
    const std::string text = ::artrace::test::read_file(log);
    EXPECT_NE(text.find(written.string() + ": cannot write: No space left on device"), std::string::npos) << command << "\n" << text;
    EXPECT_TRUE(nothing_at(written)) << command;
    EXPECT_TRUE(nothing_at(written.string() + ".partial")) << command;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
