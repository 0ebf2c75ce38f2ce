// Camera intrinsics files: Open3D JSON, OpenCV/ROS YAML and the plain intrinsics.txt, chosen by
// the first byte (the readers go by extension).
#include "fuzz_util.h"

#include "artrace/io/intrinsics_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  if (size < 1) return 0;
  const char* names[] = {"camera_intrinsic.json", "camera.yaml", "intrinsics.txt"};
  const auto file = fuzz::put(names[data[0] % 3], data + 1, size - 1);
  fuzz::expect_clean([&] { (void)io::read_camera_file(file); });
  return 0;
}
