// The PNG decoder on libdeflate against OpenCV's (libpng and zlib), differentially: where it takes
// a file, its image must be OpenCV's, pixel for pixel; where it declines, the readers use OpenCV's
// answer anyway.
//
// The first byte chooses how the rest is read (bit 0: decoded as colour, else as 16-bit depth):
//   - bit 1 clear: the rest is the file; with bit 2 set, the harness first makes every chunk's CRC
//     right, so that mutations reach past the checksums (both decoders see the same repaired file);
//   - bit 1 set: the rest is an image to write, so that the rows, their filters and the layouts are
//     explored behind a valid zlib stream: width, height, a layout (8-bit grey, grey and alpha,
//     RGB, RGBA; 16-bit grey), how the stream is split into IDATs, then the filtered rows
//     themselves (filter bytes included: a wrong one must be declined), compressed with libdeflate.
#include "../../io/src/png_decode.h"
#include "../png_writer.h"

#include <libdeflate.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

using artrace::test::Bytes;
using artrace::test::get32;
using artrace::test::put32;
using artrace::test::put_chunk;

/// Every chunk that fits in the file gets the CRC of its type and data.
void repair_crcs(Bytes& f) {
  size_t pos = 8;
  while (pos + 12 <= f.size()) {
    const size_t n = get32(f.data() + pos);
    if (n > f.size() - pos - 12) break;
    const uint32_t crc = static_cast<uint32_t>(libdeflate_crc32(0, f.data() + pos + 4, n + 4));
    for (int k = 0; k < 4; ++k) f[pos + 8 + n + k] = static_cast<uint8_t>(crc >> (24 - 8 * k));
    pos += 12 + n;
  }
}

/// A PNG written from the input's image description (see above).
Bytes write_png(const uint8_t* d, size_t n) {
  if (n < 5) return {};
  const uint32_t w = 1 + d[0] % 64, h = 1 + d[1] % 64;
  static const uint8_t kLayouts[5][2] = {{8, 0}, {8, 4}, {8, 2}, {8, 6}, {16, 0}};  // depth, colour type
  const uint8_t* layout = kLayouts[d[2] % 5];
  const size_t piece = 1 + d[3] * 16;
  const size_t channels = layout[1] == 0 ? 1 : layout[1] == 4 ? 2 : layout[1] == 2 ? 3 : 4;
  const size_t row = 1 + w * channels * layout[0] / 8;
  Bytes raw(row * h, 0);
  std::copy(d + 4, d + 4 + std::min(n - 4, raw.size()), raw.begin());
  for (size_t y = 0; y < h; ++y) raw[y * row] = static_cast<uint8_t>(raw[y * row] % 6);  // filter types 0-4, and 5
  const Bytes z = artrace::test::zlib_compress(raw);
  Bytes f = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  Bytes ihdr;
  put32(ihdr, w);
  put32(ihdr, h);
  ihdr.insert(ihdr.end(), {layout[0], layout[1], 0, 0, 0});
  put_chunk(f, "IHDR", ihdr.data(), ihdr.size());
  for (size_t i = 0; i < z.size(); i += piece) put_chunk(f, "IDAT", z.data() + i, std::min(piece, z.size() - i));
  put_chunk(f, "IEND", nullptr, 0);
  return f;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const int flags = (data[0] & 1) ? cv::IMREAD_COLOR : (cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  Bytes file;
  if (data[0] & 2) {
    file = write_png(data + 1, size - 1);
  } else {
    file.assign(data + 1, data + size);
    if (data[0] & 4) repair_crcs(file);
  }
  const cv::Mat fast = artrace::io::decode_png(file.data(), file.size(), flags);
  if (fast.empty()) return 0;
  const cv::Mat ref = cv::imdecode(cv::Mat(1, static_cast<int>(file.size()), CV_8UC1, file.data()), flags);
  if (ref.empty() || ref.type() != fast.type() || ref.size() != fast.size() || cv::norm(ref, fast, cv::NORM_INF) != 0) {
    std::fprintf(stderr, "decode_png took a file and gave %dx%d type %d; OpenCV gives %dx%d type %d%s\n", fast.cols, fast.rows,
                 fast.type(), ref.cols, ref.rows, ref.type(), ref.empty() ? " (it refuses the file)" : "");
    std::abort();
  }
  return 0;
}
