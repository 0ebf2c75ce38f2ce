// Renders virtual objects with the recording's camera and composites them over the recorded
// colour: Whitted shading of the virtual surfaces (diffuse with shadows from the virtual objects,
// mirror and glass to recursion depth 2, whose rays that leave the virtual objects look up the
// recorded colour), depth-aware occlusion (occlusion.h), and only the pixels the virtual objects'
// projected bounds cover are traced.
#pragma once

#include "artrace/ar/occlusion.h"
#include "artrace/ar/sensor_frame.h"
#include "artrace/core/two_level_scene.h"

#include <functional>
#include <vector>

namespace artrace::ar {

struct VirtualMaterial {
  enum Kind { kDiffuse, kMirror, kGlass } kind = kDiffuse;
  glm::vec3 color{0.8f};  ///< linear RGB
  float ior = 1.5f;
};

struct VirtualLight {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
};

struct CompositeOptions {
  bool occlusion = true;      ///< off: virtual objects are drawn over everything
  OcclusionOptions occlusion_options;
  bool shadows = true;
  float ambient = 0.3f;
  std::vector<VirtualLight> lights;  ///< empty: one light estimated from the frame
  int threads = 0;
};

struct CompositeStats {
  int traced_pixels = 0;
  double trace_ms = 0.0, occlusion_ms = 0.0, composite_ms = 0.0;
};

using MaterialLookup = std::function<VirtualMaterial(const core::Hit&)>;

/// The composited colour frame. `scene` must be committed, in the recording's world coordinates.
ColorImage composite(const SensorFrame& frame, const core::TwoLevelScene& scene, const MaterialLookup& material,
                     const CompositeOptions& options, CompositeStats* stats = nullptr);

/// The light used when none is given: above the camera, as bright as the frame.
VirtualLight estimate_light(const SensorFrame& frame);

}  // namespace artrace::ar
