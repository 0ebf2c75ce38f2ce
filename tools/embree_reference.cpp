#include "embree_reference.h"

#if defined(ARTRACE_HAVE_EMBREE)
#include <cstring>
#include <stdexcept>
#include <string>

namespace artrace::tools {
namespace {

/// Embree's ray layouts and packet calls of width N.
template <int N>
struct Width;
template <>
struct Width<8> {
  using Ray = RTCRay8;
  using RayHit = RTCRayHit8;
  static void intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* rh) {
    rtcIntersect8(valid, s, c, rh);
  }
  static void occluded(const int* valid, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded8(valid, s, c, r); }
};
template <>
struct Width<16> {
  using Ray = RTCRay16;
  using RayHit = RTCRayHit16;
  static void intersect(const int* valid, RTCScene s, RTCIntersectContext* c, RayHit* rh) {
    rtcIntersect16(valid, s, c, rh);
  }
  static void occluded(const int* valid, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded16(valid, s, c, r); }
};

/// Copies lanes [0, N) of the packet into Embree's N-wide ray layout; `valid` marks the lanes of `mask`.
template <int N, class R>
void fill_ray(const core::RayPacket& rays, core::LaneMask mask, R& r, int* valid) {
  static_assert(N <= core::kPacketSize, "an Embree packet is at most one of ours");
  for (int i = 0; i < N; ++i) {
    valid[i] = ((mask >> i) & 1u) ? -1 : 0;
    r.org_x[i] = rays.org[0][i];
    r.org_y[i] = rays.org[1][i];
    r.org_z[i] = rays.org[2][i];
    r.dir_x[i] = rays.dir[0][i];
    r.dir_y[i] = rays.dir[1][i];
    r.dir_z[i] = rays.dir[2][i];
    r.tnear[i] = rays.tmin[i];
    r.tfar[i] = rays.tmax[i];
    r.time[i] = 0.0f;
    r.mask[i] = 0xffffffffu;
    r.id[i] = static_cast<unsigned>(i);
    r.flags[i] = 0;
  }
}

template <int N>
void intersect_n(RTCScene scene, const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(64) int valid[N];
  alignas(64) typename Width<N>::RayHit rh;
  fill_ray<N>(rays, mask, rh.ray, valid);
  for (int i = 0; i < N; ++i) rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
  Width<N>::intersect(valid, scene, &ctx, &rh);
  for (int i = 0; i < N; ++i) {
    if ((mask >> i) & 1u) prim[i] = rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID ? core::kInvalidId : rh.hit.primID[i];
  }
}

template <int N>
core::LaneMask occluded_n(RTCScene scene, const core::RayPacket& rays, core::LaneMask mask) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(64) int valid[N];
  alignas(64) typename Width<N>::Ray r;
  fill_ray<N>(rays, mask, r, valid);
  Width<N>::occluded(valid, scene, &ctx, &r);
  core::LaneMask blocked = 0;
  for (int i = 0; i < N; ++i) {
    if (((mask >> i) & 1u) && r.tfar[i] < 0.0f) blocked |= 1u << i;
  }
  return blocked;
}

}  // namespace

EmbreeReference::EmbreeReference(const std::vector<core::Triangle>& tris, int threads) : tris_(tris) {
  const std::string config = "threads=" + std::to_string(threads);
  device_ = rtcNewDevice(config.c_str());
  if (!device_) throw std::runtime_error("Embree: cannot create a device");
  build();
}

EmbreeReference::~EmbreeReference() {
  if (scene_) rtcReleaseScene(scene_);
  if (device_) rtcReleaseDevice(device_);
}

void EmbreeReference::build() {
  if (scene_) rtcReleaseScene(scene_);
  scene_ = rtcNewScene(device_);
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                        3 * sizeof(float), 3 * tris_.size()));
  auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                             3 * sizeof(unsigned), tris_.size()));
  for (size_t i = 0; i < tris_.size(); ++i) {
    std::memcpy(v + 9 * i, &tris_[i], 9 * sizeof(float));
    idx[3 * i] = static_cast<unsigned>(3 * i);
    idx[3 * i + 1] = static_cast<unsigned>(3 * i + 1);
    idx[3 * i + 2] = static_cast<unsigned>(3 * i + 2);
  }
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_);
}

void EmbreeReference::intersect1(const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  for (int i = 0; i < core::kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    RTCRayHit rh{};
    rh.ray.org_x = rays.org[0][i];
    rh.ray.org_y = rays.org[1][i];
    rh.ray.org_z = rays.org[2][i];
    rh.ray.dir_x = rays.dir[0][i];
    rh.ray.dir_y = rays.dir[1][i];
    rh.ray.dir_z = rays.dir[2][i];
    rh.ray.tnear = rays.tmin[i];
    rh.ray.tfar = rays.tmax[i];
    rh.ray.mask = 0xffffffffu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &ctx, &rh);
    prim[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? core::kInvalidId : rh.hit.primID;
  }
}

void EmbreeReference::intersect_packet(const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim,
                                       int width) const {
  if (width == 16) {
    intersect_n<16>(scene_, rays, mask, prim);
  } else {
    intersect_n<8>(scene_, rays, mask & 0xffu, prim);
  }
}

core::LaneMask EmbreeReference::occluded_packet(const core::RayPacket& rays, core::LaneMask mask, int width) const {
  return width == 16 ? occluded_n<16>(scene_, rays, mask) : occluded_n<8>(scene_, rays, mask & 0xffu);
}

}  // namespace artrace::tools
#endif
