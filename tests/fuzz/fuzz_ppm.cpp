// PPM textures (P3 and P6, as BART's scenes use them).
#include "fuzz_util.h"

#include "artrace/io/bart_shading.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  const auto file = fuzz::put("texture.ppm", data, size);
  fuzz::expect_clean([&] { (void)io::load_ppm(file); });
  return 0;
}
