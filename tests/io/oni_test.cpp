#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <random>

#include "../test_util.h"
#include "artrace/io/oni_codecs.h"
#include "artrace/io/oni_file.h"
#include "artrace/io/oni_reader.h"
#include "artrace/io/openni2_reader.h"
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
  const auto path = ::artrace::test::scratch_path(name);
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
      bad += f.depth.at(x, y) != ar::depth_metres(depth_value(x, y, k), 1000.0);
      for (int ch = 0; ch < 3; ++ch) bad += f.color.at(x, y)[ch] != color_value(x, y, k, ch);
    }
  }
  EXPECT_EQ(bad, 0) << "frame " << k;
}

/// Frames of the project's reader and OpenNI2's file driver, read front to back, byte for byte.
void expect_same_as_openni2(const std::filesystem::path& path) {
  OniReader own(path);
  std::vector<ar::SensorFrame> ours;
  for (ar::SensorFrame f; own.next(f);) ours.push_back(f);
  OpenNi2Reader theirs(path);
  ASSERT_EQ(theirs.frame_count().value(), static_cast<int64_t>(ours.size()));
  for (size_t k = 0; k < ours.size(); ++k) {
    ar::SensorFrame f;
    ASSERT_TRUE(theirs.next(f)) << "frame " << k;
    EXPECT_EQ(f.depth.depth_m, ours[k].depth.depth_m) << "depth of frame " << k;
    EXPECT_EQ(f.color.rgb, ours[k].color.rgb) << "colour of frame " << k;
    EXPECT_DOUBLE_EQ(f.depth_time_s, ours[k].depth_time_s) << "frame " << k;
    EXPECT_DOUBLE_EQ(f.color_time_s, ours[k].color_time_s) << "frame " << k;
  }
}

/// Written by the project, read by the project's reader (every pixel, index and timestamp, and
/// frame-accurate seeks) and by OpenNI2's own file driver (the same frames).
TEST(Oni, WriterRoundTripsBitForBitAndOpenNI2Agrees) {
  const auto path = write_fixture("artrace_roundtrip.oni");
  ar::SensorFrame f;
  {
    OniReader reader(path);
    ASSERT_EQ(reader.frame_count().value(), kFrames);
    EXPECT_TRUE(reader.container().finalised());
    EXPECT_TRUE(reader.gaps().empty());
    for (int k = 0; k < kFrames; ++k) {
      ASSERT_TRUE(reader.next(f));
      expect_frame(f, k);
      EXPECT_EQ(f.depth.at(3, 0) == 0.0f, k == 2) << "no reading stays 0";
    }
    EXPECT_FALSE(reader.next(f)) << "ends after the last frame";
    for (const int k : {4, 1, 6, 0, 5}) {
      reader.seek(k);
      ASSERT_TRUE(reader.next(f));
      expect_frame(f, k);
    }
    EXPECT_THROW(reader.seek(kFrames + 1), std::out_of_range);
  }
  expect_same_as_openni2(path);
  // OpenNI's own recorder pads files with zeros after End: still a good file, without a warning
  { std::ofstream(path, std::ios::binary | std::ios::app) << std::string(5000, '\0'); }
  OniReader padded(path);
  EXPECT_TRUE(padded.warnings().empty());
  padded.seek(kFrames - 1);
  ASSERT_TRUE(padded.next(f));
  expect_frame(f, kFrames - 1);
  EXPECT_FALSE(padded.next(f));
  std::filesystem::remove(path);
}

/// The writer's seek tables and undo chain, read back: seek-table entry k holds frame k's
/// timestamp and the offset of its NewData record, and each NewData record's undo points at the
/// node's previous NewData (0 for the first). The offsets to compare with are found by walking
/// the records from the start, independently of both structures.
TEST(Oni, WriterSeekTablesAndUndoChainPointAtTheFrames) {
  const auto path = write_fixture("artrace_seek_table.oni");
  const OniContainer file(path);
  ASSERT_EQ(file.nodes().size(), 2u);
  std::map<uint64_t, OniRecord> by_offset;
  for (const OniRecord& r : file.records()) by_offset[r.offset] = r;
  for (const OniNode& n : file.nodes()) {
    ASSERT_EQ(n.frames.size(), static_cast<size_t>(kFrames));
    ASSERT_EQ(n.seek_table.size(), static_cast<size_t>(kFrames) + 1) << n.name;
    EXPECT_EQ(n.seek_table[0].offset, 0u);
    EXPECT_EQ(n.declared_frames, static_cast<uint32_t>(kFrames));
    for (int k = 0; k < kFrames; ++k) {
      EXPECT_EQ(n.seek_table[k + 1].timestamp_us, timestamp(k)) << n.name << " entry " << k + 1;
      EXPECT_EQ(n.seek_table[k + 1].offset, n.frames[k].record_offset) << n.name << " entry " << k + 1;
    }
    // walk the undo chain back from the last frame: every frame of this node, in reverse, then 0
    uint64_t at = n.frames.back().record_offset;
    for (int k = kFrames - 1; k >= 0; --k) {
      ASSERT_EQ(at, n.frames[k].record_offset) << n.name << " frame " << k;
      const OniRecord& r = by_offset.at(at);
      EXPECT_EQ(r.type, 0x0Au);
      EXPECT_EQ(r.node, n.id);
      at = r.undo;
    }
    EXPECT_EQ(at, 0u) << "the first frame's undo";
  }
  std::filesystem::remove(path);
}

TEST(Oni, AbandonedWriterLeavesNoFile) {
  const auto path = ::artrace::test::scratch_path("artrace_abandoned.oni");
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

/// Reads every frame of a copy of `bytes`; returns the frames read, or the ParseError's text.
std::string read_all(const std::string& name, const std::string& bytes, int* frames = nullptr, std::vector<std::string>* warnings = nullptr) {
  const auto path = ::artrace::test::scratch_path(name);
  std::ofstream(path, std::ios::binary) << bytes;
  std::string error;
  try {
    OniReader reader(path);
    if (warnings) *warnings = reader.warnings();
    int n = 0;
    for (ar::SensorFrame f; reader.next(f);) ++n;
    if (frames) *frames = n;
  } catch (const ParseError& e) {
    error = e.what();
  }
  std::filesystem::remove(path);
  return error;
}

/// Broken files are refused with the file and byte named, never a crash; a recording cut short is
/// read up to its last whole record, with a warning.
TEST(Oni, DamagedFilesAreRefusedWithTheFileNamed) {
  const auto good = write_fixture("artrace_damage_src.oni");
  const std::string bytes = ::artrace::test::read_file(good);
  std::filesystem::remove(good);
  struct Damage {
    const char* name;
    std::string data;
    const char* message;
  };
  std::string codec0 = bytes;
  // NodeAdded of node 1 starts at 24; its codec sits after header (28), name (4 + 6) and type (4)
  std::memset(&codec0[24 + 28 + 10 + 4], 0, 4);
  std::string unknown_codec = bytes;
  std::memcpy(&unknown_codec[24 + 28 + 10 + 4], "16zX", 4);
  std::string lying_mode = bytes;  // the depth stream claims 65 columns: its frames are too small
  lying_mode[lying_mode.find("xnMapOutputMode") + 16 + 4] = kW + 1;
  std::string huge_mode = bytes;
  huge_mode[huge_mode.find("xnMapOutputMode") + 16 + 4 + 2] = 0x7f;
  std::string high_byte = bytes;
  high_byte[high_byte.find("xnMapOutputMode") + 2] = '\xd6';
  std::string huge_fields = bytes;
  huge_fields[24 + 12 + 3] = 0x40;  // the first record's fields size, 1 GB
  const Damage cases[] = {
      {"truncated_header.oni", bytes.substr(0, 10), "not an ONI file"},
      {"codec0.oni", codec0, "which this reader does not decode"},
      {"unknown_codec.oni", unknown_codec, "codec \"16zX\""},
      {"lying_mode.oni", lying_mode, "depth frame 0 (NONE): an uncompressed 65x48 depth frame takes 6240 bytes, this one has 6144"},
      {"huge_mode.oni", huge_mode, "out of range"},
      {"high_byte_name.oni", high_byte, "name holds byte 214, outside printable ASCII"},
      {"huge_fields.oni", huge_fields, "record fields size"},
  };
  for (const Damage& d : cases) {
    const std::string error = read_all(d.name, d.data);
    EXPECT_NE(error.find(d.name), std::string::npos) << d.name << ": " << error;
    EXPECT_NE(error.find(d.message), std::string::npos) << d.name << ": " << error;
  }
  // cut short: the frames before the cut, a warning naming the byte
  int frames = 0;
  std::vector<std::string> warnings;
  EXPECT_EQ(read_all("cut_short.oni", bytes.substr(0, bytes.size() / 2), &frames, &warnings), "");
  EXPECT_GT(frames, 0);
  EXPECT_LT(frames, kFrames);
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings[0].find("past the end of the file"), std::string::npos) << warnings[0];
  // no frames at all
  const size_t first_frame = bytes.find("NIR", bytes.find("xnDeviceMaxDepth"));
  EXPECT_NE(read_all("no_frames.oni", bytes.substr(0, first_frame + 200)).find("holds no frames"), std::string::npos);
}

}  // namespace

// ---- real recordings from OpenNI 1.x (../shared/data/rgbd), against the values of
// shared/docs/oni-compressed.md section 8, worked out by an independent decoder and (where it
// plays the file) OpenNI2

namespace {

struct DepthStats {
  long valid = 0;
  int min = 0, max = 0;
  double mean = 0.0;
};

DepthStats depth_stats(const ar::DepthImage& d) {
  DepthStats s;
  s.min = 1 << 30;
  double sum = 0.0;
  for (const float m : d.depth_m) {
    if (m <= 0.0f) continue;
    const int mm = static_cast<int>(std::lround(m * 1000.0));
    ++s.valid;
    s.min = std::min(s.min, mm);
    s.max = std::max(s.max, mm);
    sum += mm;
  }
  s.mean = s.valid ? sum / s.valid : 0.0;
  return s;
}

void expect_stats(const ar::DepthImage& d, long valid, int min, int max, double mean, const char* what) {
  const DepthStats s = depth_stats(d);
  EXPECT_EQ(s.valid, valid) << what;
  EXPECT_EQ(s.min, min) << what;
  EXPECT_EQ(s.max, max) << what;
  EXPECT_NEAR(s.mean, mean, 5e-4) << what;
}

void expect_colour_mean(const ar::ColorImage& c, double r, double g, double b) {
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < c.rgb.size(); ++i) sum[i % 3] += c.rgb[i];
  const double n = static_cast<double>(c.rgb.size() / 3);
  EXPECT_NEAR(sum[0] / n, r, 5e-5);
  EXPECT_NEAR(sum[1] / n, g, 5e-5);
  EXPECT_NEAR(sum[2] / n, b, 5e-5);
}

TEST(OniReal, KinectTabletopFinalisedOpenNI1) {
  ARTRACE_REQUIRE_SHARED("rgbd/oni-kinect1-tabletop-4f/Captured.oni");
  OniReader reader(shared_path);
  const OniContainer& file = reader.container();
  EXPECT_EQ(file.version()[2], 0u) << "1.0.0.x";
  EXPECT_EQ(file.version()[3], 6u);
  EXPECT_EQ(file.record_header_size(), 24);
  EXPECT_TRUE(file.finalised());
  EXPECT_EQ(file.end_offset(), 863796u) << "End comes before the NodeRemoved and SeekTable records";
  const OniNode* depth = file.find(kOniDepth);
  const OniNode* color = file.find(kOniImage);
  ASSERT_TRUE(depth && color);
  EXPECT_EQ(depth->codec, "16zT");
  EXPECT_EQ(color->codec, "JPEG");
  EXPECT_EQ(depth->width, 640);
  EXPECT_EQ(color->height, 480);
  ASSERT_EQ(reader.frame_count().value(), 4);
  EXPECT_EQ(depth->frames.front().timestamp_us, 5276u);
  EXPECT_EQ(depth->frames.back().timestamp_us, 205492u);
  EXPECT_EQ(color->frames.front().timestamp_us, 0u);
  EXPECT_EQ(color->frames.back().timestamp_us, 200029u);
  // the seek tables (16-byte entries here) point at the frames
  for (const OniNode* n : {depth, color}) {
    ASSERT_EQ(n->seek_table.size(), 5u);
    for (size_t k = 0; k < 4; ++k) EXPECT_EQ(n->seek_table[k + 1].offset, n->frames[k].record_offset);
  }
  // dropped frames: 133 ms between the first two frames of both streams, three missing
  ASSERT_EQ(reader.gaps().size(), 2u);
  for (const OniGap& g : reader.gaps()) {
    EXPECT_EQ(g.after, 0u);
    EXPECT_NEAR(g.gap_ms, 133.4, 0.5);
    EXPECT_EQ(g.missing, 3);
  }
  EXPECT_EQ(reader.registered(), std::optional<bool>(true));
  EXPECT_DOUBLE_EQ(reader.depth_units_per_metre(), 1000.0);
  ar::SensorFrame f = reader.read(0);
  expect_stats(f.depth, 219609, 490, 2140, 1201.419, "first depth frame");
  expect_colour_mean(f.color, 142.8382, 125.0139, 131.6553);
  EXPECT_NEAR(f.depth_time_s - f.color_time_s, 0.005276, 1e-9) << "paired with the colour frame 5.3 ms before it";
  f = reader.read(3);
  expect_stats(f.depth, 221513, 488, 2153, 1198.782, "last depth frame");
  // focal length from xnFOV: (640 / 2) / tan(1.01447 / 2) = 575.8 px
  EXPECT_NEAR(f.color_intrinsics.fx, 575.8, 0.1);
}

TEST(OniReal, KinectTabletopMatchesOpenNI2FrontToBack) {
  ARTRACE_REQUIRE_SHARED("rgbd/oni-kinect1-tabletop-4f/Captured.oni");
  expect_same_as_openni2(shared_path);
}

TEST(OniReal, QvgaNeverFinalisedIsReadByScanning) {
  ARTRACE_REQUIRE_SHARED("rgbd/oni-qvga-cc-40f/test.oni");
  OniReader reader(shared_path);
  const OniContainer& file = reader.container();
  EXPECT_FALSE(file.finalised());
  EXPECT_FALSE(file.has_end());
  EXPECT_TRUE(file.warnings().empty()) << "the file ends exactly after its 80th frame record";
  const OniNode* depth = file.find(kOniDepth);
  const OniNode* color = file.find(kOniImage);
  ASSERT_TRUE(depth && color);
  EXPECT_EQ(depth->declared_frames, 0u) << "never patched";
  EXPECT_EQ(depth->width, 320);
  ASSERT_EQ(reader.frame_count().value(), 40);
  EXPECT_EQ(depth->frames.front().timestamp_us, 0u);
  EXPECT_EQ(depth->frames.back().timestamp_us, 1301401u);
  EXPECT_EQ(color->frames.front().timestamp_us, 168u);
  EXPECT_EQ(color->frames.back().timestamp_us, 1308114u);
  EXPECT_TRUE(reader.gaps().empty());
  EXPECT_EQ(reader.registered(), std::optional<bool>(false)) << "AlternativeViewPoint recorded 1, then 0";
  // every frame decodes, in pairs of equal frame number
  for (int k = 0; k < 40; ++k) {
    const ar::SensorFrame f = reader.read(k);
    EXPECT_EQ(f.depth.width, 320);
    EXPECT_EQ(f.color.width, 320);
    EXPECT_EQ(depth->frames[k].frame_number, static_cast<uint32_t>(k + 1));
    EXPECT_NEAR(f.color_time_s, color->frames[k].timestamp_us * 1e-6, 1e-12) << "frame " << k;
  }
  const ar::SensorFrame first = reader.read(0), last = reader.read(39);
  expect_stats(first.depth, 59719, 2286, 6622, 2995.886, "first depth frame");
  expect_stats(last.depth, 59664, 1663, 6375, 2982.181, "last depth frame");
  expect_colour_mean(first.color, 85.1510, 85.5456, 77.8851);
}

// Uncompressed YUV422 colour (U Y0 V Y1 for each pair of pixels): grey (U = V = 128) stays grey
// and brighter Y gives brighter pixels; an odd width is refused (found by fuzz_oni_codecs:
// OpenCV's conversion, given one, wrote past the end of the image).
TEST(OniCodecs, Yuv422DecodesPairsAndRefusesAnOddWidth) {
  const std::vector<uint8_t> frame = {128, 60, 128, 200, 128, 120, 128, 121};  // 4 x 1
  std::vector<uint8_t> rgb;
  decode_raw_rgb(frame.data(), frame.size(), 2, 4, 1, rgb);
  ASSERT_EQ(rgb.size(), 12u);
  for (int p = 0; p < 4; ++p) {
    EXPECT_EQ(rgb[3 * p], rgb[3 * p + 1]) << "pixel " << p;
    EXPECT_EQ(rgb[3 * p], rgb[3 * p + 2]) << "pixel " << p;
  }
  EXPECT_LT(rgb[0], rgb[6]);
  EXPECT_LT(rgb[6], rgb[3]);
  EXPECT_LE(rgb[6], rgb[9]);
  try {
    decode_raw_rgb(frame.data(), 6, 2, 3, 1, rgb);
    ADD_FAILURE() << "an odd width was accepted";
  } catch (const DecodeError& e) {
    EXPECT_NE(std::string(e.what()).find("a YUV422 frame needs an even width, this one is 3"), std::string::npos) << e.what();
  }
}

/// Bytes of a real 16zT/JPEG recording changed: every change is either read or refused with the
/// file named, never a crash or a hang; a 16zT stream that ends early or a table that lies is named.
TEST(OniReal, CorruptCompressedFramesAreRefusedWithTheByte) {
  ARTRACE_REQUIRE_SHARED("rgbd/oni-kinect1-tabletop-4f/Captured.oni");
  const std::string bytes = ::artrace::test::read_file(shared_path);
  const OniContainer file(shared_path);
  const OniFrameRecord d0 = file.find(kOniDepth)->frames[0];
  // the 16zT stream of the first depth frame ends early: its last bytes become 0xE0 (no values)
  std::string short_stream = bytes;
  std::memset(&short_stream[d0.data_offset + d0.data_size - 2000], 0xE0, 2000);
  const std::string e1 = read_all("short_16zT.oni", short_stream);
  EXPECT_NE(e1.find("depth frame 0 (16zT): the frame decodes to"), std::string::npos) << e1;
  EXPECT_NE(e1.find("short_16zT.oni @ byte "), std::string::npos) << e1;
  // the table size lies: more entries than the frame holds bytes
  std::string lying_table = bytes;
  lying_table[d0.data_offset] = lying_table[d0.data_offset + 1] = '\xff';
  EXPECT_NE(read_all("lying_table.oni", lying_table).find("16zT table of"), std::string::npos);
  // a JPEG that is not one
  const OniFrameRecord c1 = file.find(kOniImage)->frames[1];
  std::string not_jpeg = bytes;
  not_jpeg[c1.data_offset] = 0;
  EXPECT_NE(read_all("not_jpeg.oni", not_jpeg).find("colour frame 1 (JPEG): not a JPEG image"), std::string::npos);
  // a JPEG whose frame header (baseline SOF0: FF C0, length, precision, height, width) declares
  // 30000 x 30000: refused against the stream's mode before anything is decoded (or allocated)
  std::string huge_jpeg = bytes;
  const size_t sof = huge_jpeg.find("\xff\xc0", c1.data_offset);
  ASSERT_LT(sof, static_cast<size_t>(c1.data_offset + c1.data_size));
  for (const size_t at : {sof + 5, sof + 7}) {
    huge_jpeg[at] = static_cast<char>(30000 >> 8);
    huge_jpeg[at + 1] = static_cast<char>(30000 & 255);
  }
  const std::string e2 = read_all("huge_jpeg.oni", huge_jpeg);
  EXPECT_NE(e2.find("colour frame 1 (JPEG): the JPEG image declares 30000x30000 pixels, the stream's mode 640x480"), std::string::npos) << e2;
  // random byte changes in the frames
  std::mt19937 rng(29);
  std::uniform_int_distribution<size_t> at(d0.data_offset, bytes.size() - 1);
  for (int k = 0; k < 40; ++k) {
    std::string m = bytes;
    for (int j = 0; j < 8; ++j) m[at(rng)] = static_cast<char>(rng());
    const std::string e = read_all("mutant.oni", m);
    if (!e.empty()) {
      EXPECT_NE(e.find("mutant.oni"), std::string::npos) << e;
    }
  }
}

}  // namespace
}  // namespace artrace::io
