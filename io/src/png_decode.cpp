#include "png_decode.h"

#include "cv_convert.h"

#include <libdeflate.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

namespace artrace::io {

namespace {

constexpr uint32_t kMaxChunk = 0x7FFFFFFFu;       // PNG's chunk lengths are 31-bit
constexpr uint32_t kMaxAncillaryChunk = 8000000;  // libpng's default limit on a chunk it reads

uint32_t be32(const uint8_t* p) {
  return static_cast<uint32_t>(p[0]) << 24 | static_cast<uint32_t>(p[1]) << 16 | static_cast<uint32_t>(p[2]) << 8 | p[3];
}
bool is_letter(uint8_t c) { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z'); }
bool is_type(const uint8_t* p, const char* t) { return std::memcmp(p, t, 4) == 0; }
/// The CRC of a chunk (over its type and data) matches the one stored after it.
bool crc_ok(const uint8_t* chunk, uint32_t length) {
  return static_cast<uint32_t>(libdeflate_crc32(0, chunk + 4, length + 4)) == be32(chunk + 8 + length);
}

struct FreeDecompressor {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};
libdeflate_decompressor* decompressor() {
  thread_local std::unique_ptr<libdeflate_decompressor, FreeDecompressor> d(libdeflate_alloc_decompressor());
  return d.get();
}

uint8_t paeth(uint8_t a, uint8_t b, uint8_t c) {
  const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

/// The Sub filter undone on a row of `B`-byte pixels, the pixel to the left held in registers.
template <size_t B>
void sub_pixels(uint8_t* x, size_t row_bytes) {
  uint8_t left[B];
  std::memcpy(left, x, B);
  for (size_t i = B; i < row_bytes; i += B) {
    for (size_t k = 0; k < B; ++k) x[i + k] = left[k] = static_cast<uint8_t>(x[i + k] + left[k]);
  }
}

/// A row of `C`-channel 8-bit pixels (grey, grey and alpha, RGB, RGBA) as BGR: alpha dropped,
/// grey repeated, as libpng gives OpenCV.
template <int C>
void to_bgr(const uint8_t* in, uint8_t* o, int width) {
  for (int x = 0; x < width; ++x, in += C, o += 3) {
    if constexpr (C >= 3) {
      o[0] = in[2];
      o[1] = in[1];
      o[2] = in[0];
    } else {
      o[0] = o[1] = o[2] = in[0];
    }
  }
}

/// Undoes the row filters in place: `raw` holds `height` rows of a filter-type byte and
/// `row_bytes` bytes; `bpp` bytes make a pixel. False on a filter type other than 0-4.
bool unfilter(uint8_t* raw, size_t height, size_t row_bytes, size_t bpp) {
  const std::vector<uint8_t> zero(row_bytes, 0);
  const uint8_t* prior = zero.data();
  for (size_t y = 0; y < height; ++y) {
    uint8_t* row = raw + y * (row_bytes + 1);
    const uint8_t type = row[0];
    uint8_t* x = row + 1;
    switch (type) {
      case 0:
        break;
      case 1:  // the common filter (every row of the TUM frames): by pixel for the usual sizes
        if (bpp == 3) {
          sub_pixels<3>(x, row_bytes);
        } else if (bpp == 2) {
          sub_pixels<2>(x, row_bytes);
        } else if (bpp == 4) {
          sub_pixels<4>(x, row_bytes);
        } else {
          for (size_t i = bpp; i < row_bytes; ++i) x[i] = static_cast<uint8_t>(x[i] + x[i - bpp]);
        }
        break;
      case 2:
        for (size_t i = 0; i < row_bytes; ++i) x[i] = static_cast<uint8_t>(x[i] + prior[i]);
        break;
      case 3:
        for (size_t i = 0; i < bpp; ++i) x[i] = static_cast<uint8_t>(x[i] + (prior[i] >> 1));
        for (size_t i = bpp; i < row_bytes; ++i) x[i] = static_cast<uint8_t>(x[i] + ((x[i - bpp] + prior[i]) >> 1));
        break;
      case 4:
        for (size_t i = 0; i < bpp; ++i) x[i] = static_cast<uint8_t>(x[i] + prior[i]);  // a = c = 0: b
        for (size_t i = bpp; i < row_bytes; ++i) x[i] = static_cast<uint8_t>(x[i] + paeth(x[i - bpp], prior[i], prior[i - bpp]));
        break;
      default:
        return false;
    }
    prior = x;
  }
  return true;
}

}  // namespace

cv::Mat decode_png(const uint8_t* d, size_t size, int flags) {
  const bool want_colour = flags == cv::IMREAD_COLOR, want_depth = flags == (cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if ((!want_colour && !want_depth) || size < 8 + 25 || std::memcmp(d, kPngSignature, 8) != 0) return {};
  // IHDR first, 13 bytes
  if (be32(d + 8) != 13 || !is_type(d + 12, "IHDR") || !crc_ok(d + 8, 13)) return {};
  const uint8_t* h = d + 16;
  const uint32_t width = be32(h), height = be32(h + 4);
  const uint8_t depth = h[8], colour_type = h[9];
  if (width == 0 || height == 0 || width > kMaxImageSide || height > kMaxImageSide) return {};
  if (h[10] != 0 || h[11] != 0 || h[12] != 0) return {};  // deflate, adaptive filtering, not interlaced
  int channels = 0;
  if (want_colour && depth == 8) channels = colour_type == 0 ? 1 : colour_type == 2 ? 3 : colour_type == 4 ? 2 : colour_type == 6 ? 4 : 0;
  if (want_depth && depth == 16 && colour_type == 0) channels = 1;
  if (channels == 0) return {};
  const size_t bpp = static_cast<size_t>(channels) * (depth / 8), row_bytes = bpp * width;
  const size_t raw_size = (row_bytes + 1) * height;
  const size_t idat_limit = raw_size + 6 + 5 * (raw_size / 32566 + 1);  // stored blocks' overhead at most

  // per-thread buffers, reused from frame to frame (no allocation, no zeroing)
  thread_local std::vector<uint8_t> stream, raw;
  struct Trim {  // a rare large image's buffers are not kept
    ~Trim() {
      constexpr size_t kKeep = size_t{64} << 20;
      if (stream.capacity() > kKeep) std::vector<uint8_t>().swap(stream);
      if (raw.capacity() > kKeep) std::vector<uint8_t>().swap(raw);
    }
  } trim;
  stream.clear();
  // the chunks up to IEND: IDAT's data gathered (its chunks must follow one another), the
  // ancillary chunks skipped as libpng does for OpenCV (none changes the pixels it asks for)
  bool seen_idat = false, idat_done = false, seen_iend = false;
  size_t pos = 8 + 25;
  while (pos + 12 <= size) {
    const uint8_t* c = d + pos;
    const uint32_t length = be32(c);
    if (length > kMaxChunk || length > size - pos - 12) return {};
    const uint8_t* type = c + 4;
    if (!is_letter(type[0]) || !is_letter(type[1]) || !is_letter(type[2]) || !is_letter(type[3])) return {};
    if (is_type(type, "IDAT")) {
      if (idat_done || length > idat_limit || !crc_ok(c, length)) return {};
      seen_idat = true;
      stream.insert(stream.end(), c + 8, c + 8 + length);
    } else {
      if (seen_idat) idat_done = true;
      if (is_type(type, "IEND")) {
        if (length != 0 || !crc_ok(c, 0)) return {};
        seen_iend = true;
        break;
      }
      // a critical chunk (PLTE and unknown ones), transparency or an orientation: OpenCV's way
      if (!(type[0] & 0x20) || is_type(type, "tRNS") || is_type(type, "eXIf") || length > kMaxAncillaryChunk) return {};
    }
    pos += 12 + static_cast<size_t>(length);
  }
  if (!seen_idat || !seen_iend || stream.size() < 2) return {};
  if ((stream[0] >> 4) != 7) return {};  // a zlib window smaller than 32 KiB: zlib may refuse distances libdeflate takes
  // deflate expands 1,032 times at most: a stream too short for the rows is refused before the
  // rows are allocated (a 20-byte file declaring 16384 x 16384 RGBA would cost 1 GB)
  if (raw_size / 1032 > stream.size()) return {};

  if (raw.size() < raw_size) raw.resize(raw_size);
  size_t in_used = 0, out_made = 0;
  if (libdeflate_zlib_decompress_ex(decompressor(), stream.data(), stream.size(), raw.data(), raw_size, &in_used, &out_made) !=
          LIBDEFLATE_SUCCESS ||
      in_used != stream.size() || out_made != raw_size) {
    return {};
  }
  if (!unfilter(raw.data(), height, row_bytes, bpp)) return {};

  const int w = static_cast<int>(width), rows = static_cast<int>(height);
  if (want_depth) {
    cv::Mat out(rows, w, CV_16UC1);
    for (int y = 0; y < rows; ++y) {
      const uint8_t* in = raw.data() + static_cast<size_t>(y) * (row_bytes + 1) + 1;
      uint16_t* o = out.ptr<uint16_t>(y);
      for (int x = 0; x < w; ++x) o[x] = static_cast<uint16_t>(in[2 * x] << 8 | in[2 * x + 1]);
    }
    return out;
  }
  cv::Mat out(rows, w, CV_8UC3);
  for (int y = 0; y < rows; ++y) {
    const uint8_t* in = raw.data() + static_cast<size_t>(y) * (row_bytes + 1) + 1;
    uint8_t* o = out.ptr<uint8_t>(y);
    switch (channels) {
      case 1: to_bgr<1>(in, o, w); break;
      case 2: to_bgr<2>(in, o, w); break;
      case 3: to_bgr<3>(in, o, w); break;
      default: to_bgr<4>(in, o, w); break;
    }
  }
  return out;
}

}  // namespace artrace::io
