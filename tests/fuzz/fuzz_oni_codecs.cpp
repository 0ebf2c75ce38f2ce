// The ONI stream decoders on their own: 16z (with and without the embedded table of 16zT), JPEG
// and raw colour. A 4-byte header chooses the decoder and the frame size (up to 64x48), the rest is
// the compressed frame.
#include "fuzz_util.h"

#include "artrace/io/oni_codecs.h"

#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  if (size < 4) return 0;
  const int which = data[0] % 4;
  const int width = 1 + data[1] % 64, height = 1 + data[2] % 48, format = data[3];
  const uint8_t* body = data + 4;
  const size_t n = size - 4;
  fuzz::expect_clean([&] {
    if (which < 2) {
      std::vector<uint16_t> out(static_cast<size_t>(width) * height);
      io::decode_16z(body, n, which == 1, out.size(), out.data());
    } else if (which == 2) {
      std::vector<uint8_t> rgb;
      io::decode_jpeg_rgb(body, n, width, height, rgb);
    } else {
      std::vector<uint8_t> rgb;
      io::decode_raw_rgb(body, n, format, width, height, rgb);
    }
  });
  return 0;
}
