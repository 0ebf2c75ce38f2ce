// AFF scenes (the BART format), with includes: the input is the scene and also "inc.aff", which
// scenes can include ("i 0 inc.aff"), itself included: nesting and loops too.
#include "fuzz_util.h"

#include "artrace/io/aff_scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  const auto scene = fuzz::put("scene.aff", data, size);
  fuzz::put("inc.aff", data, size);
  fuzz::expect_clean([&] {
    const io::AffScene s = io::load_aff(scene);
    (void)s.triangles_at(0.0);
    (void)s.triangles_at(0.5);
    (void)s.camera_at(0.0, 32, 24);
  });
  return 0;
}
