// The TUM layout's text files: the first byte chooses the reader (rgb.txt/depth.txt lists, a
// trajectory, intrinsics.txt), the rest is the file.
#include "fuzz_util.h"

#include "artrace/io/tum_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  if (size < 1) return 0;
  const int which = data[0] % 3;
  const auto file = fuzz::put(which == 0 ? "rgb.txt" : which == 1 ? "groundtruth.txt" : "intrinsics.txt", data + 1, size - 1);
  fuzz::expect_clean([&] {
    if (which == 0) {
      const auto list = io::read_tum_list(file);
      (void)io::associate(list, list, 0.02);
    } else if (which == 1) {
      const ar::Trajectory t = io::read_tum_trajectory(file);
      if (!t.empty()) (void)t.at(t.samples().front().time_s + 0.01);
    } else {
      (void)io::read_intrinsics(file);
    }
  });
  return 0;
}
