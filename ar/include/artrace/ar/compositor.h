// Renders virtual objects with the recording's camera and composites them over the recorded
// colour: Whitted shading of the virtual surfaces (diffuse with shadows from the virtual objects,
// mirror and glass to recursion depth 2), depth-aware occlusion (occlusion.h), and the virtual
// objects' effect on the real scene through the depth proxy (depth_proxy.h):
//   - shadows on real surfaces by differential rendering: at each real point the sensor saw, the
//     recorded colour is scaled by (ambient + light reaching it) / (ambient + light that would
//     reach it without the virtual objects), per light with the cosine of the depth map's normal,
//     so only the change the virtual objects cause is applied;
//   - reflection and refraction rays that leave the virtual objects meet the depth mesh and take
//     the recorded colour there (falling back to a look-up along the ray where the mesh has holes).
// Only pixels the virtual objects' projected bounds cover are traced for them, and only real
// points whose ray to a light crosses the virtual objects' bounds get a shadow ray.
#pragma once

#include "artrace/ar/depth_proxy.h"
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

/// The share of light a surface of `m` lets through to a shadow ray: glass passes what Fresnel
/// leaves at normal incidence, tinted by its colour (the mean of the channels, since a shadow
/// ray carries one number); anything else passes nothing. Give it to the scene as its
/// triangles' transmittance (TwoLevelScene::set_static_transmittance, set_mesh_transmittance,
/// set_deformable_transmittance) and the glass's shadows come out lighter than an opaque
/// object's, in the compositor's shadows among the virtual objects and on the real surfaces alike.
float shadow_transmittance(const VirtualMaterial& m);

struct VirtualLight {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
};

struct CompositeOptions {
  bool occlusion = true;      ///< off: virtual objects are drawn over everything
  OcclusionOptions occlusion_options;
  bool shadows = true;        ///< shadows among the virtual objects and on the real surfaces
  bool real_shadows = true;   ///< with `shadows`: the virtual objects' shadows on real surfaces
  bool real_reflections = true;  ///< reflection/refraction rays meet the depth mesh
  DepthProxy* proxy = nullptr;   ///< kept across frames by the caller; null: a local one
  /// World boxes of the virtual objects, one per object (tighter than the scene's bounds, so fewer
  /// real points need a shadow ray); empty: the scene's bounds.
  std::vector<core::Aabb> object_bounds;
  float ambient = 0.3f;
  std::vector<VirtualLight> lights;  ///< empty: one light estimated from the frame
  int threads = 0;
};

struct CompositeStats {
  int traced_pixels = 0;
  int shadow_rays_real = 0;     ///< shadow rays from real points that met the virtual bounds
  int shadowed_real_pixels = 0;  ///< real pixels darkened by a virtual object
  double trace_ms = 0.0, occlusion_ms = 0.0, composite_ms = 0.0;
  double proxy_ms = 0.0, real_shadow_ms = 0.0;
};

using MaterialLookup = std::function<VirtualMaterial(const core::Hit&)>;

/// The composited colour frame. `scene` must be committed, in the recording's world coordinates.
ColorImage composite(const SensorFrame& frame, const core::TwoLevelScene& scene, const MaterialLookup& material,
                     const CompositeOptions& options, CompositeStats* stats = nullptr);

/// The light used when none is given: above the camera, as bright as the frame.
VirtualLight estimate_light(const SensorFrame& frame);

}  // namespace artrace::ar
