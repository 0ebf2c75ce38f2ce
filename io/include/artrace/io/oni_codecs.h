// Decoders of the frame codecs found in ONI recordings, written from shared/docs/oni-compressed.md
// (itself from OpenNI's XnStreamCompression.cpp and XnJpegCodec.cpp, Apache-2.0): PrimeSense's
// 16-bit depth compression "16zP" and its variant with an embedded value table "16zT", and JPEG
// colour (through OpenCV's imdecode, libjpeg-turbo, which is what OpenNI itself links). Every
// decoder checks its input: a stream that ends early, produces more or fewer values than the
// frame's size, or names a table entry that does not exist throws DecodeError with the byte.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace artrace::io {

/// A malformed frame: `byte` is the offset in the frame's data where decoding failed.
class DecodeError : public std::runtime_error {
 public:
  DecodeError(size_t byte, const std::string& what) : std::runtime_error(what), byte_(byte) {}
  size_t byte() const { return byte_; }

 private:
  size_t byte_;
};

/// 16zP (`embedded_table` false) or 16zT (true): exactly `count` values into `out`.
void decode_16z(const uint8_t* data, size_t size, bool embedded_table, size_t count, uint16_t* out);

/// A JPEG frame to `width` x `height` RGB (3 bytes a pixel, R first). Throws DecodeError when it
/// does not decode or has another size.
void decode_jpeg_rgb(const uint8_t* data, size_t size, int width, int height, std::vector<uint8_t>& rgb);

/// Uncompressed colour in OpenNI 1.x's xnPixelFormat (1 RGB24, 2 YUV422 as U Y0 V Y1, 3 GRAY8)
/// to RGB. Throws DecodeError when the size does not match or the format is another.
void decode_raw_rgb(const uint8_t* data, size_t size, int pixel_format, int width, int height, std::vector<uint8_t>& rgb);

}  // namespace artrace::io
