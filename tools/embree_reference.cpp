#include "embree_reference.h"

#if defined(ARTRACE_HAVE_EMBREE)
#include <cstring>
#include <stdexcept>
#include <string>

namespace artrace::tools {
namespace {

/// Copies the packet's lanes into Embree's 8-wide ray layout; `valid` marks the lanes of `mask`.
void fill_ray8(const core::RayPacket& rays, core::LaneMask mask, RTCRay8& r, int* valid) {
  for (int i = 0; i < 8; ++i) {
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

void EmbreeReference::intersect8(const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(32) int valid[8];
  alignas(32) RTCRayHit8 rh;
  fill_ray8(rays, mask, rh.ray, valid);
  for (int i = 0; i < 8; ++i) rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect8(valid, scene_, &ctx, &rh);
  for (int i = 0; i < 8; ++i) {
    if ((mask >> i) & 1u) prim[i] = rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID ? core::kInvalidId : rh.hit.primID[i];
  }
}

core::LaneMask EmbreeReference::occluded8(const core::RayPacket& rays, core::LaneMask mask) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(32) int valid[8];
  alignas(32) RTCRay8 r;
  fill_ray8(rays, mask, r, valid);
  rtcOccluded8(valid, scene_, &ctx, &r);
  core::LaneMask blocked = 0;
  for (int i = 0; i < 8; ++i) {
    if (((mask >> i) & 1u) && r.tfar[i] < 0.0f) blocked |= 1u << i;
  }
  return blocked;
}

}  // namespace artrace::tools
#endif
