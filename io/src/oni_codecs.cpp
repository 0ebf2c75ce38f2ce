#include "artrace/io/oni_codecs.h"
#include "cv_convert.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstring>
#include <optional>

namespace artrace::io {

namespace {

/// The code stream of 16zP/16zT from `pos`: values (depths, or table indices) into out[0, count).
/// Returns false where the stream is malformed (ends inside an escape, passes `count` values, or
/// ends short of it), with `bad` the byte and `why` the problem; the caller turns that into an
/// error. One branch per byte kind and one bound check per byte: the decoder runs at a few
/// hundred megabytes a second.
bool decode_codes(const uint8_t* in, size_t size, size_t pos, uint16_t cur, size_t count, uint16_t* out, size_t& bad, std::string& why) {
  uint16_t* o = out;
  uint16_t* const end = out + count;
  if (o == end) {
    bad = pos;
    why = "the frame holds no values";
    return false;
  }
  *o++ = cur;
  while (pos < size) {
    const uint8_t c = in[pos];
    // at most 2 values for a byte, or a run of at most 30: checked before writing
    if (c < 0xE0) {
      if (end - o < 2) {
        // the frame's last value: one nibble, with the low one padding or an escape
        const uint8_t lo = c & 0x0F;
        if (o == end || (lo != 0x0D && lo != 0x0F)) {
          bad = pos;
          why = "the frame decodes to more than its " + std::to_string(count) + " values";
          return false;
        }
      }
      cur = static_cast<uint16_t>(cur + 6 - (c >> 4));
      *o++ = cur;
      const uint8_t lo = c & 0x0F;
      ++pos;
      if (lo == 0x0F) {
        goto escape;
      } else if (lo != 0x0D) {  // D: padding, no second value
        cur = static_cast<uint16_t>(cur + 6 - lo);
        *o++ = cur;
      }
      continue;
    } else if (c == 0xFF) {
      ++pos;
      goto escape;
    } else {
      const size_t run = 2 * static_cast<size_t>(c - 0xE0);  // repeats of the current value
      if (static_cast<size_t>(end - o) < run) {
        bad = pos;
        why = "a run of " + std::to_string(run) + " values passes the frame's " + std::to_string(count);
        return false;
      }
      for (size_t k = 0; k < run; ++k) o[k] = cur;
      o += run;
      ++pos;
      continue;
    }
  escape:
    if (pos >= size) {
      bad = pos;
      why = "frame ends inside an escape";
      return false;
    }
    if (o == end) {
      bad = pos;
      why = "the frame decodes to more than its " + std::to_string(count) + " values";
      return false;
    }
    if (in[pos] & 0x80) {
      cur = static_cast<uint16_t>(cur + 192 - in[pos]);  // a difference in [-63, +64]
      pos += 1;
    } else {
      if (pos + 1 >= size) {
        bad = pos;
        why = "frame ends inside an absolute value";
        return false;
      }
      cur = static_cast<uint16_t>(in[pos] << 8 | in[pos + 1]);  // big-endian, the format's one exception
      pos += 2;
    }
    *o++ = cur;
  }
  if (o != end) {
    bad = size;
    why = "the frame decodes to " + std::to_string(o - out) + " values, not its " + std::to_string(count);
    return false;
  }
  return true;
}

}  // namespace

void decode_16z(const uint8_t* in, size_t size, bool table, size_t count, uint16_t* out) {
  size_t pos = 0, entries = 0;
  if (table) {
    if (size < 2) throw DecodeError(0, "16zT frame of " + std::to_string(size) + " bytes has no table size");
    entries = static_cast<size_t>(in[0]) | static_cast<size_t>(in[1]) << 8;
    pos = 2 + 2 * entries;
    if (pos > size) throw DecodeError(0, "16zT table of " + std::to_string(entries) + " entries runs past the frame's " + std::to_string(size) + " bytes");
  }
  if (pos + 2 > size) throw DecodeError(pos, "frame ends before its first value");
  const uint16_t first = static_cast<uint16_t>(in[pos] | in[pos + 1] << 8);
  size_t bad = 0;
  std::string why;
  if (!decode_codes(in, size, pos + 2, first, count, out, bad, why)) throw DecodeError(bad, why);
  if (!table) return;
  // indices to depths through the table, little-endian u16 entries after the count
  uint16_t lut[65536];
  for (size_t k = 0; k < entries; ++k) lut[k] = static_cast<uint16_t>(in[2 + 2 * k] | in[3 + 2 * k] << 8);
  uint16_t top = 0;
  for (size_t k = 0; k < count; ++k) top = std::max(top, out[k]);
  if (top >= entries) {
    // where: the first value past the table, found again (the error path only)
    size_t k = 0;
    while (out[k] < entries) ++k;
    throw DecodeError(0, "value " + std::to_string(k) + " names table entry " + std::to_string(out[k]) + " of a table with " +
                             std::to_string(entries) + " entries");
  }
  for (size_t k = 0; k < count; ++k) out[k] = lut[out[k]];
}

void decode_jpeg_rgb(const uint8_t* data, size_t size, int width, int height, std::vector<uint8_t>& rgb) {
  if (size < 4 || data[0] != 0xFF || data[1] != 0xD8) throw DecodeError(0, "not a JPEG image (no FF D8 marker)");
  // the size the image declares must be the stream's mode: checked before OpenCV allocates for it
  const std::optional<ImageSize> declared = declared_image_size(data, size);
  if (!declared) throw DecodeError(0, "the JPEG image has no frame header (SOF marker)");
  const auto mismatch = [&](const char* what, uint32_t w, uint32_t h) {
    return DecodeError(0, std::string("the JPEG image ") + what + " " + std::to_string(w) + "x" + std::to_string(h) + " pixels, the stream's mode " +
                              std::to_string(width) + "x" + std::to_string(height));
  };
  if (declared->width != static_cast<uint32_t>(width) || declared->height != static_cast<uint32_t>(height)) {
    throw mismatch("declares", declared->width, declared->height);
  }
  const cv::Mat buf(1, static_cast<int>(size), CV_8UC1, const_cast<uint8_t*>(data));
  const cv::Mat bgr = cv::imdecode(buf, cv::IMREAD_COLOR);
  if (bgr.empty()) throw DecodeError(0, "the JPEG image does not decode");
  if (bgr.cols != width || bgr.rows != height) throw mismatch("decodes to", static_cast<uint32_t>(bgr.cols), static_cast<uint32_t>(bgr.rows));
  rgb.resize(static_cast<size_t>(width) * height * 3);
  cv::Mat out(height, width, CV_8UC3, rgb.data());
  cv::cvtColor(bgr, out, cv::COLOR_BGR2RGB);
}

void decode_raw_rgb(const uint8_t* data, size_t size, int format, int width, int height, std::vector<uint8_t>& rgb) {
  const size_t pixels = static_cast<size_t>(width) * height;
  const size_t bpp = format == 1 ? 3 : format == 2 ? 2 : format == 3 ? 1 : 0;
  if (bpp == 0) throw DecodeError(0, "uncompressed colour in pixel format " + std::to_string(format) + " (this reader takes 1 RGB24, 2 YUV422, 3 GRAY8)");
  // YUV422 packs two pixels in four bytes (U Y0 V Y1): an odd width is no such frame (and OpenCV's
  // conversion, given one, reads and writes past the rows: found by fuzz_oni_codecs)
  if (format == 2 && width % 2 != 0) throw DecodeError(0, "a YUV422 frame needs an even width, this one is " + std::to_string(width));
  if (size != pixels * bpp) {
    throw DecodeError(0, "an uncompressed " + std::to_string(width) + "x" + std::to_string(height) + " frame takes " + std::to_string(pixels * bpp) +
                             " bytes, this one has " + std::to_string(size));
  }
  rgb.resize(pixels * 3);
  if (format == 1) {
    std::memcpy(rgb.data(), data, pixels * 3);
    return;
  }
  const cv::Mat in(height, width, format == 2 ? CV_8UC2 : CV_8UC1, const_cast<uint8_t*>(data));
  cv::Mat out(height, width, CV_8UC3, rgb.data());
  cv::cvtColor(in, out, format == 2 ? cv::COLOR_YUV2RGB_UYVY : cv::COLOR_GRAY2RGB);
}

}  // namespace artrace::io
