// AR scene files (JSON): models (the project's own, beside the scene), materials, lights,
// animation, anchors; then the scene is built for a frame as the compositor uses it.
#include "fuzz_util.h"

#include "artrace/io/ar_scene.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  artrace::fuzz::provide("data/models/spinning_box.gltf", "spinning_box.gltf");
  artrace::fuzz::provide("data/models/glass_sphere.gltf", "glass_sphere.gltf");
  artrace::fuzz::provide("data/models/bending_tube.gltf", "bending_tube.gltf");
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  const auto file = fuzz::put("scene.json", data, size);
  fuzz::expect_clean([&] {
    io::ArSceneFile s = io::load_ar_scene(file);
    io::ArRuntime rt(s);
    rt.update(0.0);
    rt.update(1.5);
  });
  return 0;
}
