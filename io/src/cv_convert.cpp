#include "cv_convert.h"

#include "artrace/io/parse_error.h"
#include "png_decode.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <fstream>
#include <limits>
#include <vector>

namespace artrace::io {

ar::ColorImage color_from_bgr(const cv::Mat& bgr) {
  ar::ColorImage c;
  c.width = bgr.cols;
  c.height = bgr.rows;
  c.rgb.resize(static_cast<size_t>(bgr.cols) * bgr.rows * 3);
  cv::Mat rgb(bgr.rows, bgr.cols, CV_8UC3, c.rgb.data());
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return c;
}

ar::DepthImage depth_from_u16(const cv::Mat& raw, double per_metre) {
  ar::DepthImage d;
  d.width = raw.cols;
  d.height = raw.rows;
  d.depth_m.resize(static_cast<size_t>(raw.cols) * raw.rows);
  for (int y = 0; y < raw.rows; ++y) {
    const uint16_t* row = raw.ptr<uint16_t>(y);
    float* out = d.depth_m.data() + static_cast<size_t>(y) * raw.cols;
    for (int x = 0; x < raw.cols; ++x) out[x] = (row[x] == 0 || row[x] == 65535) ? 0.0f : ar::depth_metres(row[x], per_metre);
  }
  return d;
}

std::string png_chunk_error(const uint8_t* d, size_t size) {
  if (size < 8 || !std::equal(kPngSignature, kPngSignature + 8, d)) return "";
  size_t pos = 8;
  while (pos + 8 <= size) {
    const uint64_t length = static_cast<uint64_t>(d[pos]) << 24 | d[pos + 1] << 16 | d[pos + 2] << 8 | d[pos + 3];
    const std::string type(reinterpret_cast<const char*>(d + pos + 4), 4);
    if (length + 12 > size - pos) {
      return "its " + type + " chunk at byte " + std::to_string(pos) + " declares " + std::to_string(length) + " bytes, " +
             std::to_string(size - pos < 12 ? 0 : size - pos - 12) + " follow";
    }
    if (type == "IEND") return "";
    pos += 12 + length;
  }
  return "";
}

std::optional<ImageSize> declared_image_size(const uint8_t* d, size_t size) {
  const auto be16 = [&](size_t i) { return static_cast<uint32_t>(d[i] << 8 | d[i + 1]); };
  const auto be32 = [&](size_t i) { return be16(i) << 16 | be16(i + 2); };
  if (size >= 24 && std::equal(kPngSignature, kPngSignature + 8, d) && std::equal(d + 12, d + 16, "IHDR")) return ImageSize{be32(16), be32(20)};
  // WebP (EXT_texture_webp): a RIFF file whose first chunk is VP8 (lossy: 14-bit sizes in the
  // key frame header), VP8L (lossless: 14-bit sizes less one, packed) or VP8X (24-bit canvas sizes
  // less one)
  if (size >= 30 && std::equal(d, d + 4, "RIFF") && std::equal(d + 8, d + 12, "WEBP")) {
    const auto le16 = [&](size_t i) { return static_cast<uint32_t>(d[i] | d[i + 1] << 8); };
    const auto le24 = [&](size_t i) { return static_cast<uint32_t>(d[i] | d[i + 1] << 8 | d[i + 2] << 16); };
    if (std::equal(d + 12, d + 16, "VP8 ")) return ImageSize{le16(26) & 0x3FFF, le16(28) & 0x3FFF};
    if (std::equal(d + 12, d + 16, "VP8L")) {
      const uint32_t bits = le16(21) | le16(23) << 16;
      return ImageSize{(bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1};
    }
    if (std::equal(d + 12, d + 16, "VP8X")) return ImageSize{le24(24) + 1, le24(27) + 1};
    return std::nullopt;
  }
  if (size < 4 || d[0] != 0xFF || d[1] != 0xD8) return std::nullopt;
  // JPEG: walk the marker segments (FF xx, then a big-endian length that counts itself) to the
  // first start-of-frame marker, SOF0..SOF15 less DHT (C4), JPG (C8) and DAC (CC)
  size_t pos = 2;
  while (pos + 4 <= size) {
    if (d[pos] != 0xFF) return std::nullopt;
    const uint8_t m = d[pos + 1];
    if (m == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (m == 0x01 || (m >= 0xD0 && m <= 0xD7)) {  // markers without a segment
      pos += 2;
      continue;
    }
    const uint32_t len = be16(pos + 2);
    if (m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC) {
      if (len < 7 || pos + 9 > size) return std::nullopt;
      return ImageSize{be16(pos + 7), be16(pos + 5)};  // precision, height, width
    }
    if (m == 0xDA || m == 0xD9 || len < 2) return std::nullopt;  // scan data before a frame header
    pos += 2 + len;
  }
  return std::nullopt;
}

std::string image_header_error(const uint8_t* data, size_t size) {
  if (const std::string bad = png_chunk_error(data, size); !bad.empty()) return "is a broken PNG: " + bad;
  const std::optional<ImageSize> declared = declared_image_size(data, size);
  if (declared && (declared->width == 0 || declared->height == 0 || declared->width > kMaxImageSide || declared->height > kMaxImageSide)) {
    return "declares " + std::to_string(declared->width) + "x" + std::to_string(declared->height) + " pixels (images of 1 to " +
           std::to_string(kMaxImageSide) + " pixels a side are read)";
  }
  return "";
}

cv::Mat read_depth_png(const std::filesystem::path& path, const cv::Mat& bgr) {
  const cv::Mat raw = read_image_file(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if (raw.empty()) throw ParseError(path.string(), 0, 0, "cannot decode the depth image (missing, truncated or not an image)");
  if (raw.type() != CV_16UC1) {
    throw ParseError(path.string(), 0, 0, "depth PNG must be 16-bit with one channel, got OpenCV type " + std::to_string(raw.type()));
  }
  if (raw.cols != bgr.cols || raw.rows != bgr.rows) {
    throw ParseError(path.string(), 0, 0, "depth is " + std::to_string(raw.cols) + "x" + std::to_string(raw.rows) + ", colour " +
                                              std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows));
  }
  return raw;
}

cv::Mat read_image_file(const std::filesystem::path& path, int flags) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return cv::Mat();
  const std::streamoff size = in.tellg();
  if (size <= 0 || size > std::numeric_limits<int>::max()) return cv::Mat();
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), size)) return cv::Mat();
  if (const std::string bad = image_header_error(bytes.data(), bytes.size()); !bad.empty()) throw ParseError(path.string(), 0, 0, "the image " + bad);
  if (cv::Mat fast = decode_png(bytes.data(), bytes.size(), flags); !fast.empty()) return fast;
  return cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<uint8_t*>(bytes.data())), flags);
}

}  // namespace artrace::io
