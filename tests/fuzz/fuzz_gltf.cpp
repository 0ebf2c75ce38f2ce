// glTF models: JSON (.gltf) or binary (.glb, by its magic), with an image file beside them that
// they may refer to ("texture.png") and a folder ("data"), then the node transforms and morph weights of its clips.
#include "fuzz_util.h"

#include "artrace/io/gltf_model.h"

#include <cstring>

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  artrace::fuzz::provide("tests/data/fuzz/texture.png", "texture.png");
  // a folder beside the model, for uris that name one ("data" once took tinygltf's reader to a
  // folder, whose size it read as 2^63 - 1 bytes and allocated)
  std::filesystem::create_directories(artrace::fuzz::scratch() / "data");
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace artrace;
  const bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  const auto file = fuzz::put(glb ? "model.glb" : "model.gltf", data, size);
  fuzz::expect_clean([&] {
    const io::GltfModel m = io::load_gltf(file);
    (void)m.triangle_count();
    for (int clip = -1; clip < static_cast<int>(m.animations.size()) && clip < 3; ++clip) {
      for (const float t : {0.0f, 0.37f, 1e3f}) {
        (void)m.node_transforms(clip, t);
        (void)m.node_weights(clip, t);
      }
    }
  });
  return 0;
}
