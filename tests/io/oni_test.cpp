#include <fstream>

#include "../test_util.h"
#include "artrace/io/oni_file.h"
#include "artrace/io/oni_reader.h"
#include "artrace/io/oni_writer.h"
#include "artrace/io/parse_error.h"

namespace artrace::io {
namespace {

constexpr int kW = 64, kH = 48, kFrames = 7;

uint16_t depth_value(int x, int y, int k) {
  return static_cast<uint16_t>(k == 2 && x == 3 ? 0 : 1000 + x + 7 * y + 13 * k);
}
uint8_t color_value(int x, int y, int k, int c) {
  return static_cast<uint8_t>(c == 0 ? 4 * x : c == 1 ? 5 * y : 30 * k + c);
}
uint64_t timestamp(int k) { return 1000000 + 33333ull * k; }

std::filesystem::path write_fixture(const std::string &name) {
  const auto path = std::filesystem::temp_directory_path() / name;
  OniWriter w(path, {kW, kH, 30}, {kW, kH, 30}, 8000);
  std::vector<uint16_t> d(kW * kH);
  std::vector<uint8_t> c(kW * kH * 3);
  for (int k = 0; k < kFrames; ++k) {
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) {
        d[y * kW + x] = depth_value(x, y, k);
        for (int ch = 0; ch < 3; ++ch) c[3 * (y * kW + x) + ch] = color_value(x, y, k, ch);
      }
    }
    w.write(d.data(), c.data(), timestamp(k));
  }
  w.close();
  return path;
}

void expect_frame(const ar::SensorFrame &f, int k) {
  ASSERT_EQ(f.index, k);
  ASSERT_EQ(f.depth.width, kW);
  ASSERT_EQ(f.color.height, kH);
  EXPECT_DOUBLE_EQ(f.depth_time_s, timestamp(k) * 1e-6);
  EXPECT_DOUBLE_EQ(f.color_time_s, timestamp(k) * 1e-6);
  int bad = 0;
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      bad += f.depth.at(x, y) != depth_value(x, y, k) * 1e-3f;
      for (int ch = 0; ch < 3; ++ch) bad += f.color.at(x, y)[ch] != color_value(x, y, k, ch);
    }
  }
  EXPECT_EQ(bad, 0) << "frame " << k;
}

/// Written by the project, played by OpenNI2's own file driver: every pixel,
/// index and timestamp.
TEST(Oni, WriterRoundTripsThroughOpenNI2BitForBit) {
  const auto path = write_fixture("artrace_roundtrip.oni");
  const OniFileInfo info = inspect_oni(path);
  ASSERT_EQ(info.nodes.size(), 2u);
  EXPECT_EQ(info.nodes[0].frames, static_cast<uint32_t>(kFrames));
  EXPECT_EQ(info.nodes[1].width, kW);
  ar::SensorFrame f;
  {
    OniReader reader(path);
    ASSERT_EQ(reader.frame_count().value(), kFrames);
    for (int k = 0; k < kFrames; ++k) {
      ASSERT_TRUE(reader.next(f));
      expect_frame(f, k);
      EXPECT_EQ(f.depth.at(3, 0) == 0.0f, k == 2) << "no reading stays 0";
    }
    EXPECT_FALSE(reader.next(f)) << "ends at the End record";
    // frame-accurate seek, backwards and forwards
    for (const int k : {4, 1, 6, 0, 5}) {
      reader.seek(k);
      ASSERT_TRUE(reader.next(f));
      expect_frame(f, k);
    }
    EXPECT_THROW(reader.seek(kFrames + 1), std::out_of_range);
  }
  // OpenNI's own recorder pads files with zeros after End: still a good file
  { std::ofstream(path, std::ios::binary | std::ios::app) << std::string(5000, '\0'); }
  OniReader padded(path);
  padded.seek(kFrames - 1);
  ASSERT_TRUE(padded.next(f));
  expect_frame(f, kFrames - 1);
  EXPECT_FALSE(padded.next(f));
  std::filesystem::remove(path);
}

TEST(Oni, AbandonedWriterLeavesNoFile) {
  const auto path = std::filesystem::temp_directory_path() / "artrace_abandoned.oni";
  std::filesystem::remove(path);
  {
    OniWriter w(path, {kW, kH, 30}, {kW, kH, 30});
    std::vector<uint16_t> d(kW * kH, 1000);
    std::vector<uint8_t> c(kW * kH * 3, 9);
    w.write(d.data(), c.data(), 1);
    // no close(): as if the export were interrupted
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".partial"));
}

/// Truncated and corrupted copies are refused with the file and byte named,
/// never a crash.
TEST(Oni, DamagedFilesAreRefusedWithTheFileNamed) {
  const auto good = write_fixture("artrace_damage_src.oni");
  std::ifstream in(good, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  struct Damage {
    const char *name;
    std::string data;
    const char *message;
  };
  std::string bad_magic = bytes;
  bad_magic[100] ^= 0x55;
  std::string codec0 = bytes;
  // NodeAdded of node 1 starts at 24; its codec sits after header (28), name (4
  // + 6) and type (4)
  std::memset(&codec0[24 + 28 + 10 + 4], 0, 4);
  // a property name with a byte outside ASCII (OpenNI2's player crashed on it: found by fuzzing
  // `artrace info`), and a stream without its xnCropping (the player would wait for frames in vain)
  std::string high_byte = bytes;
  high_byte[high_byte.find("xnMapOutputMode") + 2] = '\xd6';
  std::string no_cropping = bytes;
  no_cropping[no_cropping.find("xnCropping") + 2] = 'Q';
  const Damage cases[] = {
      {"truncated_header.oni", bytes.substr(0, 10), "not an ONI file"},
      {"truncated_middle.oni", bytes.substr(0, bytes.size() / 2), "truncated"},
      {"no_end.oni", bytes.substr(0, bytes.size() - 28), "no End record"},
      {"garbled.oni", bad_magic, "corrupt"},
      {"codec0.oni", codec0, "codec 0"},
      {"high_byte_name.oni", high_byte, "name holds byte 214, outside printable ASCII"},
      {"no_cropping.oni", no_cropping, "before its xnCropping property"},
  };
  for (const Damage &d : cases) {
    const auto path = std::filesystem::temp_directory_path() / d.name;
    std::ofstream(path, std::ios::binary) << d.data;
    try {
      OniReader reader(path);
      ADD_FAILURE() << d.name << " was accepted";
    } catch (const ParseError &e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(d.message), std::string::npos) << d.name << ": " << e.what();
    }
    std::filesystem::remove(path);
  }
  std::filesystem::remove(good);
}

}  // namespace
}  // namespace artrace::io
