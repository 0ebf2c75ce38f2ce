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
#include "artrace/ar/plane_fit.h"
#include "artrace/ar/real_scene.h"
#include "artrace/ar/sensor_frame.h"
#include "artrace/core/two_level_scene.h"

#include <functional>
#include <vector>

namespace artrace::ar {

/// What a virtual surface looks like at one point (the material lookup fills it per hit).
///   - kDiffuse without `pbr`: Lambert, as the project's own models and the AR scene's "diffuse"
///     override have it;
///   - kDiffuse with `pbr`: glTF's metallic-roughness: a Lambert lobe for the dielectric part and
///     a GGX specular lobe (Walter et al., "Microfacet Models for Refraction through Rough
///     Surfaces", EGSR 2007; Smith-Schlick masking, Schlick's Fresnel from F0 = 0.04 for
///     dielectrics and the base colour for metals) for the point lights; the ambient light
///     reflected as F0 (a uniform white environment); a mirror reflection ray, weighted by
///     Fresnel, that fades in as roughness falls below 0.2 (a perfect mirror at roughness 0);
///   - kMirror: a perfect mirror tinted by `color`; kGlass: Fresnel-weighted reflection and
///     refraction.
struct VirtualMaterial {
  enum Kind { kDiffuse, kMirror, kGlass } kind = kDiffuse;
  glm::vec3 color{0.8f};  ///< base colour, linear RGB (factor x texture x vertex colour)
  float ior = 1.5f;
  bool pbr = false;       ///< metallic-roughness shading (see above)
  float metallic = 0.0f;
  float roughness = 1.0f;
  glm::vec3 emissive{0.0f};  ///< added to the shaded colour (linear RGB)
  float occlusion = 1.0f;    ///< ambient occlusion: scales the ambient term
  /// Coverage in [0, 1] (glTF alpha BLEND): below 1 the surface is blended over what lies behind it.
  float alpha = 1.0f;
  /// Rays pass through this point as if nothing were there (glTF alpha MASK below its cutoff, or a
  /// back face of a single-sided material): camera, shadow and secondary rays alike.
  bool cutout = false;
  /// Shading normal in world space (interpolated vertex normals, normal maps); zero: the geometric
  /// normal. It is turned to the side the ray comes from, as the geometric normal is.
  glm::vec3 normal{0.0f};
};

/// A hit as the material lookup sees it: the hit, the ray's direction, and the width of the ray
/// cone there (world units, for the textures' level of detail).
struct SurfaceQuery : core::Hit {
  SurfaceQuery() = default;
  explicit SurfaceQuery(const core::Hit& h) : core::Hit(h) {}
  glm::vec3 dir{0.0f, 0.0f, 1.0f};
  float cone_width = 0.0f;
  bool shadow_ray = false;  ///< asked by a shadow ray (back faces of single-sided surfaces still cast shadows)
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
  OcclusionOptions occlusion_options;  ///< its `threads` is not read: the compositor's own `threads` counts
  bool shadows = true;        ///< shadows among the virtual objects and on the real surfaces
  bool real_shadows = true;   ///< with `shadows`: the virtual objects' shadows on real surfaces
  bool real_reflections = true;  ///< reflection/refraction rays meet the depth mesh
  DepthProxy* proxy = nullptr;   ///< kept across frames by the caller; null: a local one
  /// A fused model of the room (real_scene.h), the real scene instead of the per-frame depth mesh:
  /// reflections and refractions meet it (also outside the view), its depth stands in where the
  /// sensor saw the same surface noisily or not at all (within 3 sigma of its noise, or a hole),
  /// its normals serve the shadows on real surfaces, and it shadows the virtual objects.
  const FusedRoom* room = nullptr;
  /// Planes the virtual objects stand on (their anchors'): where the sensor's depth lies within 3
  /// sigma of its noise of one (or has no reading on it, inside the objects' screen bounds), the
  /// plane's depth is taken, so occlusion does not flicker where an object touches the surface.
  std::vector<Plane> support_planes;
  /// World boxes of the virtual objects, one per object (tighter than the scene's bounds, so fewer
  /// real points need a shadow ray); empty: the scene's bounds.
  std::vector<core::Aabb> object_bounds;
  float ambient = 0.3f;
  std::vector<VirtualLight> lights;  ///< empty: one light estimated from the frame
  /// Some material has cut-outs or blends (alpha MASK or BLEND): rays then walk past cut-out
  /// points, and shadow rays ask the material at every surface they cross.
  bool alpha_tested = false;
  int threads = 0;
  /// Secondary rays (reflection, refraction) and the shadow rays at their hits are traced in
  /// packets, one generation after the other. Off: only the first generation goes in packets and
  /// the later ones are traced one ray at a time (the reference the packets are tested against).
  bool packet_generations = true;
  /// Keep the occlusion's visibility and the virtual depth of every pixel in the stats (tests,
  /// benchmarks).
  bool keep_visibility = false;
};

struct CompositeStats {
  int traced_pixels = 0;
  int shadow_area_pixels = 0;    ///< pixels whose real points may lie in a virtual shadow (its rectangle)
  int shadow_rays_real = 0;     ///< shadow rays from real points that met the virtual bounds
  int shadowed_real_pixels = 0;  ///< real pixels darkened by a virtual object
  double trace_ms = 0.0, occlusion_ms = 0.0, composite_ms = 0.0;
  double proxy_ms = 0.0, real_shadow_ms = 0.0;
  double real_depth_ms = 0.0;  ///< the sensor's depth cleaned with the fused room or support planes
  /// With CompositeOptions::keep_visibility: per pixel, how much of the virtual surface shows
  /// (occlusion alpha, 0 where there is none), and the virtual surface's depth (+inf: none).
  std::vector<float> visibility, virtual_depth;
};

/// The material at a hit. A lookup taking `const core::Hit&` serves too (a SurfaceQuery is a Hit).
using MaterialLookup = std::function<VirtualMaterial(const SurfaceQuery&)>;

/// The composited colour frame. `scene` must be committed, in the recording's world coordinates.
ColorImage composite(const SensorFrame& frame, const core::TwoLevelScene& scene, const MaterialLookup& material,
                     const CompositeOptions& options, CompositeStats* stats = nullptr);

/// The sensor's depth with the fused room and the support planes of `options` where they know the
/// surface better (see CompositeOptions::room and support_planes), over pixels [x0, x1) x [y0, y1)
/// (planes fill holes only inside it); `normals` (optional) gets their normals there, zero elsewhere.
DepthImage clean_depth(const SensorFrame& frame, const CompositeOptions& options, int x0, int y0, int x1, int y1,
                       std::vector<glm::vec3>* normals = nullptr);

/// The light used when none is given: above the camera, as bright as the frame.
VirtualLight estimate_light(const SensorFrame& frame);

}  // namespace artrace::ar
