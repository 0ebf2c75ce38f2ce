// ONI recordings: the container scanned, then up to 8 frames paired and decoded (16zP/16zT depth,
// JPEG or raw colour), and a seek back, as replay and export read them.
#include "fuzz_util.h"

#include "artrace/io/oni_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  const auto file = fuzz::put("recording.oni", data, size);
  fuzz::expect_clean([&] {
    io::OniReader r(file);
    ar::SensorFrame f;
    for (int k = 0; k < 8 && r.next(f); ++k) {
    }
    if (r.frame_count().value_or(0) > 1) {
      r.seek(1);
      r.next(f);
    }
  });
  return 0;
}
