// The PNG decoder on libdeflate against two oracles: OpenCV's imdecode (libpng and zlib, another
// decoder) and the pixels the test wrote. The PNGs are written here, by a writer that applies each
// of the five row filters in the specification's own terms, so every filter, pixel layout, split
// of the compressed stream and ancillary chunk is met; and every file the decoder declines must
// come out of read_image_file exactly as OpenCV decodes it.
#include "../../io/src/cv_convert.h"
#include "../../io/src/png_decode.h"
#include "../png_writer.h"
#include "../test_util.h"

#include <libdeflate.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <utility>
#include <vector>


namespace artrace::io {
namespace {

using test::Bytes;
using test::put32;
using test::zlib_compress;

void put_chunk(Bytes& out, const std::string& type, const Bytes& data) { test::put_chunk(out, type.c_str(), data.data(), data.size()); }

/// The specification's predictor for filter type f (ISO/IEC 15948, 9.2-9.4): a the byte a pixel to
/// the left, b the byte above, c the byte above and to the left.
int predictor(int f, int a, int b, int c) {
  switch (f) {
    case 1: return a;
    case 2: return b;
    case 3: return (a + b) / 2;
    case 4: {
      const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
      if (pa <= pb && pa <= pc) return a;
      if (pb <= pc) return b;
      return c;
    }
    default: return 0;
  }
}

struct Png {
  uint32_t width = 1, height = 1;
  uint8_t depth = 8, colour_type = 2;
  Bytes samples;                      ///< the rows' bytes, unfiltered (16-bit samples big-endian)
  int filter_shift = 0;               ///< row y gets filter (y + filter_shift) % 5; 5: all Paeth
  size_t idat_piece = 0;              ///< the compressed stream split into IDATs of this size (0: one)
  std::vector<std::pair<std::string, Bytes>> before_idat, after_idat;

  int channels() const { return colour_type == 0 ? 1 : colour_type == 4 ? 2 : colour_type == 2 ? 3 : 4; }
  size_t bpp() const { return static_cast<size_t>(channels()) * depth / 8; }
  size_t row_bytes() const { return bpp() * width; }

  Bytes filtered() const {
    Bytes raw;
    const size_t n = row_bytes(), p = bpp();
    for (size_t y = 0; y < height; ++y) {
      const int f = filter_shift == 5 ? 4 : static_cast<int>((y + filter_shift) % 5);
      raw.push_back(static_cast<uint8_t>(f));
      const uint8_t* row = samples.data() + y * n;
      const uint8_t* above = y > 0 ? row - n : nullptr;
      for (size_t i = 0; i < n; ++i) {
        const int a = i >= p ? row[i - p] : 0, b = above ? above[i] : 0, c = above && i >= p ? above[i - p] : 0;
        raw.push_back(static_cast<uint8_t>(row[i] - predictor(f, a, b, c)));
      }
    }
    return raw;
  }

  Bytes file(Bytes stream = {}) const {
    if (stream.empty()) stream = zlib_compress(filtered());
    Bytes out = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
    Bytes ihdr;
    put32(ihdr, width);
    put32(ihdr, height);
    ihdr.insert(ihdr.end(), {depth, colour_type, 0, 0, 0});
    put_chunk(out, "IHDR", ihdr);
    for (const auto& [type, data] : before_idat) put_chunk(out, type, data);
    const size_t piece = idat_piece == 0 ? stream.size() : idat_piece;
    for (size_t i = 0; i < stream.size(); i += piece) {
      put_chunk(out, "IDAT", Bytes(stream.begin() + static_cast<long>(i), stream.begin() + static_cast<long>(std::min(stream.size(), i + piece))));
    }
    for (const auto& [type, data] : after_idat) put_chunk(out, type, data);
    put_chunk(out, "IEND", {});
    return out;
  }
};

/// Random samples with flat patches (where Paeth's a, b and c tie) and a ramp.
Bytes test_samples(const Png& png, std::mt19937& rng) {
  Bytes s(png.row_bytes() * png.height);
  std::uniform_int_distribution<int> byte(0, 255);
  for (size_t y = 0; y < png.height; ++y) {
    for (size_t i = 0; i < png.row_bytes(); ++i) {
      const size_t x = i / png.bpp();
      uint8_t v = static_cast<uint8_t>(byte(rng));
      if (y % 4 == 1 && x < png.width / 2) v = 200;      // flat
      if (y % 4 == 2) v = static_cast<uint8_t>(3 * x + y);  // ramp
      s[y * png.row_bytes() + i] = v;
    }
  }
  return s;
}

cv::Mat opencv(const Bytes& b, int flags) { return cv::imdecode(cv::Mat(1, static_cast<int>(b.size()), CV_8UC1, const_cast<uint8_t*>(b.data())), flags); }

bool same(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty()) return a.empty() == b.empty();
  return a.type() == b.type() && a.size() == b.size() && cv::norm(a, b, cv::NORM_INF) == 0;
}

constexpr int kColour = cv::IMREAD_COLOR, kDepth = cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR;

TEST(PngDecode, EveryFilterAndLayoutGivesTheWrittenPixelsAsOpenCvDoes) {
  std::mt19937 rng(7);
  struct Layout {
    uint8_t depth, colour_type;
    int flags;
  };
  const Layout layouts[] = {{8, 0, kColour}, {8, 4, kColour}, {8, 2, kColour}, {8, 6, kColour}, {16, 0, kDepth}};
  const std::pair<uint32_t, uint32_t> sizes[] = {{1, 1}, {37, 23}, {64, 5}};
  for (const Layout& l : layouts) {
    for (const auto& [w, h] : sizes) {
      for (int shift = 0; shift <= 5; ++shift) {
        Png png;
        png.width = w;
        png.height = h;
        png.depth = l.depth;
        png.colour_type = l.colour_type;
        png.filter_shift = shift;
        png.samples = test_samples(png, rng);
        png.idat_piece = shift % 2 ? 7 : 0;
        if (shift % 3 == 0) png.before_idat = {{"gAMA", {0, 0, 0xB1, 0x8F}}, {"tEXt", {'k', 0, 'v'}}};
        if (shift % 3 == 1) png.after_idat = {{"tEXt", {'k', 0, 'v'}}};
        const Bytes file = png.file();
        const std::string what = "depth " + std::to_string(l.depth) + ", colour type " + std::to_string(l.colour_type) + ", " +
                                 std::to_string(w) + "x" + std::to_string(h) + ", filters from " + std::to_string(shift);
        const cv::Mat got = decode_png(file.data(), file.size(), l.flags);
        ASSERT_FALSE(got.empty()) << what << ": declined";
        EXPECT_TRUE(same(got, opencv(file, l.flags))) << what << ": differs from OpenCV's";
        // the written samples, as OpenCV lays them out
        const int ch = png.channels();
        for (uint32_t y = 0; y < h; ++y) {
          const uint8_t* row = png.samples.data() + y * png.row_bytes();
          for (uint32_t x = 0; x < w; ++x) {
            const uint8_t* px = row + x * png.bpp();
            if (l.depth == 16) {
              ASSERT_EQ(got.at<uint16_t>(static_cast<int>(y), static_cast<int>(x)), px[0] << 8 | px[1]) << what;
            } else {
              const cv::Vec3b bgr = got.at<cv::Vec3b>(static_cast<int>(y), static_cast<int>(x));
              const cv::Vec3b want = ch >= 3 ? cv::Vec3b(px[2], px[1], px[0]) : cv::Vec3b(px[0], px[0], px[0]);
              ASSERT_EQ(bgr, want) << what << " at " << x << "," << y;
            }
          }
        }
      }
    }
  }
}

/// Files the decoder must decline, and read_image_file's answer for each is OpenCV's.
TEST(PngDecode, DeclinesWhatItDoesNotTakeAndOpenCvAnswers) {
  std::mt19937 rng(11);
  Png base;
  base.width = 19;
  base.height = 9;
  base.samples = test_samples(base, rng);
  base.idat_piece = 50;
  const Bytes good = base.file();
  ASSERT_FALSE(decode_png(good.data(), good.size(), kColour).empty());

  std::vector<std::pair<std::string, Bytes>> cases;
  auto with = [&](const std::string& name, auto change) {
    Png p = base;
    change(p);
    cases.push_back({name, p.file()});
  };
  with("transparency chunk", [](Png& p) { p.before_idat = {{"tRNS", {0, 1, 0, 2, 0, 3}}}; });
  with("palette chunk", [](Png& p) { p.before_idat = {{"PLTE", {1, 2, 3}}}; });
  with("unknown critical chunk", [](Png& p) { p.before_idat = {{"ABCD", {1}}}; });
  with("IDAT chunks apart", [](Png& p) { p.after_idat = {{"tEXt", {'k', 0, 'v'}}, {"IDAT", {}}}; });
  with("16-bit RGB for colour", [&](Png& p) {
    p.depth = 16;
    p.samples = test_samples(p, rng);
  });
  const Bytes stream = zlib_compress(base.filtered());
  {
    Bytes s = stream;
    s[s.size() - 1] ^= 1;  // the Adler-32 of the inflated rows
    cases.push_back({"wrong Adler-32", base.file(s)});
    Bytes extra = stream;
    extra.push_back(0);
    cases.push_back({"data after the zlib stream", base.file(extra)});
    Bytes raw = base.filtered();
    raw[3 * (base.row_bytes() + 1)] = 5;  // filter type 5 in row 3
    cases.push_back({"filter type 5", base.file(zlib_compress(raw))});
    raw = base.filtered();
    raw.resize(raw.size() - base.row_bytes() - 1);
    cases.push_back({"a row short", base.file(zlib_compress(raw))});
    raw = base.filtered();
    raw.insert(raw.end(), raw.begin(), raw.begin() + static_cast<long>(base.row_bytes() + 1));
    cases.push_back({"a row too many", base.file(zlib_compress(raw))});
    Bytes small = stream;  // a 16 KiB window: CMF 0x68, FCHECK made again
    small[0] = 0x68;
    small[1] = static_cast<uint8_t>(small[1] & 0xE0);
    small[1] = static_cast<uint8_t>(small[1] + (31 - (small[0] * 256 + small[1]) % 31) % 31);
    cases.push_back({"16 KiB zlib window", base.file(small)});
  }
  {
    Bytes f = good;
    f[8 + 25 + 8 + 50] ^= 0x40;  // the first IDAT's CRC (its 50 bytes of data intact)
    cases.push_back({"IDAT CRC", f});
    // one byte of IHDR's data (from byte 16) changed, its CRC (bytes 29-32) made again
    auto with_ihdr = [&](const std::string& name, size_t at, uint8_t value) {
      Bytes g = good;
      g[16 + at] = value;
      const uint32_t crc = static_cast<uint32_t>(libdeflate_crc32(0, g.data() + 12, 17));
      for (int k = 0; k < 4; ++k) g[29 + k] = static_cast<uint8_t>(crc >> (24 - 8 * k));
      cases.push_back({name, g});
    };
    with_ihdr("palette colour type", 9, 3);
    with_ihdr("interlaced", 12, 1);
    f = good;
    f.resize(f.size() - 12);
    cases.push_back({"no IEND", f});
  }
  cases.push_back({"8-bit grey for depth", good});  // asked with kDepth below

  const std::filesystem::path dir = ::artrace::test::scratch_path("artrace_png");
  std::filesystem::create_directories(dir);
  for (const auto& [name, bytes] : cases) {
    const int flags = name == "8-bit grey for depth" ? kDepth : kColour;
    EXPECT_TRUE(decode_png(bytes.data(), bytes.size(), flags).empty()) << name << ": taken";
    const std::filesystem::path file = dir / "f.png";
    std::ofstream(file, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    EXPECT_TRUE(same(read_image_file(file, flags), opencv(bytes, flags))) << name << ": read_image_file is not OpenCV's answer";
  }
  std::filesystem::remove_all(dir);
}

TEST(PngDecode, TumFramesDecodeAsOpenCvDecodesThem) {
  ARTRACE_REQUIRE_SHARED("rgbd/tum-fr1-rpy");
  int n = 0;
  for (const char* sub : {"rgb", "depth"}) {
    std::vector<std::filesystem::path> files;
    for (const auto& e : std::filesystem::directory_iterator(shared_path / sub)) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    ASSERT_GE(files.size(), 12u);
    for (size_t i = 0; i < files.size(); i += files.size() / 12) {
      std::ifstream in(files[i], std::ios::binary);
      const Bytes bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      const int flags = std::string(sub) == "rgb" ? kColour : kDepth;
      const cv::Mat got = decode_png(bytes.data(), bytes.size(), flags);
      ASSERT_FALSE(got.empty()) << files[i] << ": declined";
      EXPECT_TRUE(same(got, opencv(bytes, flags))) << files[i];
      ++n;
    }
  }
  EXPECT_GE(n, 24);
}

}  // namespace
}  // namespace artrace::io
