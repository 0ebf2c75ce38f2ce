#include "embree_reference.h"

#if defined(ARTRACE_HAVE_EMBREE)
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

namespace artrace::tools {
namespace {

template <int N>
struct Width;
template <>
struct Width<1> {  // rtcIntersect1 / rtcOccluded1 take no valid mask
  using RayHit = RTCRayHit;
  using Ray = RTCRay;
  static void intersect(const int*, RTCScene s, RTCIntersectContext* c, RayHit* rh) { rtcIntersect1(s, c, rh); }
  static void occluded(const int*, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded1(s, c, r); }
};
template <>
struct Width<4> {
  using RayHit = RTCRayHit4;
  using Ray = RTCRay4;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* rh) { rtcIntersect4(v, s, c, rh); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded4(v, s, c, r); }
};
template <>
struct Width<8> {
  using RayHit = RTCRayHit8;
  using Ray = RTCRay8;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* rh) { rtcIntersect8(v, s, c, rh); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded8(v, s, c, r); }
};
template <>
struct Width<16> {
  using RayHit = RTCRayHit16;
  using Ray = RTCRay16;
  static void intersect(const int* v, RTCScene s, RTCIntersectContext* c, RayHit* rh) { rtcIntersect16(v, s, c, rh); }
  static void occluded(const int* v, RTCScene s, RTCIntersectContext* c, Ray* r) { rtcOccluded16(v, s, c, r); }
};

/// 64-byte aligned storage of `n` records of `size` bytes.
struct Aligned {
  void* data = nullptr;
  size_t bytes = 0;
  void reset(size_t n) {
    std::free(data);
    bytes = n;
    data = n ? std::aligned_alloc(64, (n + 63) / 64 * 64) : nullptr;
    if (n && !data) throw std::bad_alloc();
    if (n) std::memset(data, 0, n);
  }
  ~Aligned() { std::free(data); }
};

}  // namespace

struct EmbreeBatch::Impl {
  Aligned pristine, live;
  /// width ints a call. Embree wants a packet's valid mask aligned as its rays (16, 32 or 64
  /// bytes); its AVX-512 kernels fault on a vector's 16-byte alignment
  Aligned valid_bytes;
  int* valid = nullptr;
  /// For each call: our packet, and the lane of its first Embree lane (width 1: the lane itself).
  std::vector<std::pair<uint32_t, int>> origin;
  size_t record = 0;  ///< bytes a call
  size_t packets = 0;
};

EmbreeBatch::EmbreeBatch(const std::vector<core::RayPacket>& packets, const std::vector<core::LaneMask>& masks, int width)
    : impl_(std::make_unique<Impl>()), width_(width) {
  Impl& b = *impl_;
  b.packets = packets.size();
  if (width == 1) {
    for (size_t p = 0; p < packets.size(); ++p)
      for (int i = 0; i < core::kPacketSize; ++i)
        if ((masks[p] >> i) & 1u) b.origin.push_back({static_cast<uint32_t>(p), i});
    b.record = sizeof(RTCRayHit);
    calls_ = b.origin.size();
    b.pristine.reset(calls_ * b.record);
    auto* rh = static_cast<RTCRayHit*>(b.pristine.data);
    for (size_t c = 0; c < calls_; ++c) {
      const core::RayPacket& r = packets[b.origin[c].first];
      const int i = b.origin[c].second;
      RTCRayHit& h = rh[c];
      h.ray.org_x = r.org[0][i];
      h.ray.org_y = r.org[1][i];
      h.ray.org_z = r.org[2][i];
      h.ray.dir_x = r.dir[0][i];
      h.ray.dir_y = r.dir[1][i];
      h.ray.dir_z = r.dir[2][i];
      h.ray.tnear = r.tmin[i];
      h.ray.tfar = r.tmax[i];
      h.ray.mask = 0xffffffffu;
      h.ray.flags = 0;
      h.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    }
  } else {
    if (width != 4 && width != 8 && width != 16) throw std::invalid_argument("Embree packets are 4, 8 or 16 wide");
    // one call per width-lane block of each packet that has a lane in it
    for (size_t p = 0; p < packets.size(); ++p)
      for (int o = 0; o < core::kPacketSize; o += width)
        if ((masks[p] >> o) & ((1u << width) - 1u)) b.origin.push_back({static_cast<uint32_t>(p), o});
    b.record = width == 4 ? sizeof(RTCRayHit4) : width == 8 ? sizeof(RTCRayHit8) : sizeof(RTCRayHit16);
    calls_ = b.origin.size();
    b.pristine.reset(calls_ * b.record);
    b.valid_bytes.reset(calls_ * static_cast<size_t>(width) * sizeof(int));
    b.valid = static_cast<int*>(b.valid_bytes.data);
    auto fill = [&](auto* rh) {
      for (size_t c = 0; c < calls_; ++c) {
        const core::RayPacket& r = packets[b.origin[c].first];
        const int o = b.origin[c].second;
        for (int k = 0; k < width; ++k) {
          const int i = o + k;
          b.valid[c * width + k] = ((masks[b.origin[c].first] >> i) & 1u) ? -1 : 0;
          rh[c].ray.org_x[k] = r.org[0][i];
          rh[c].ray.org_y[k] = r.org[1][i];
          rh[c].ray.org_z[k] = r.org[2][i];
          rh[c].ray.dir_x[k] = r.dir[0][i];
          rh[c].ray.dir_y[k] = r.dir[1][i];
          rh[c].ray.dir_z[k] = r.dir[2][i];
          rh[c].ray.tnear[k] = r.tmin[i];
          rh[c].ray.tfar[k] = r.tmax[i];
          rh[c].ray.mask[k] = 0xffffffffu;
          rh[c].ray.flags[k] = 0;
          rh[c].ray.id[k] = static_cast<unsigned>(k);
          rh[c].hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        }
      }
    };
    if (width == 4) fill(static_cast<RTCRayHit4*>(b.pristine.data));
    else if (width == 8) fill(static_cast<RTCRayHit8*>(b.pristine.data));
    else fill(static_cast<RTCRayHit16*>(b.pristine.data));
  }
  b.live.reset(b.pristine.bytes);
  restore();
  first_call_.assign(packets.size() + 1, calls_);
  for (size_t c = calls_; c-- > 0;) first_call_[b.origin[c].first] = c;
  for (size_t p = packets.size(); p-- > 0;) first_call_[p] = std::min(first_call_[p], first_call_[p + 1]);
}

EmbreeBatch::~EmbreeBatch() = default;

void EmbreeBatch::restore() { std::memcpy(impl_->live.data, impl_->pristine.data, impl_->pristine.bytes); }

const char* to_string(EmbreeQuality q) { return q == EmbreeQuality::kHigh ? "HIGH" : "MEDIUM"; }

EmbreeReference::EmbreeReference(const std::vector<core::Triangle>& tris, int threads, bool robust)
    : tris_(tris), robust_(robust) {
  const std::string config = "threads=" + std::to_string(threads);
  device_ = rtcNewDevice(config.c_str());
  if (!device_) throw std::runtime_error("Embree: cannot create a device");
  build(EmbreeQuality::kHigh);
  build(EmbreeQuality::kMedium);
}

EmbreeReference::~EmbreeReference() {
  for (RTCScene s : scenes_) {
    if (s) rtcReleaseScene(s);
  }
  if (device_) rtcReleaseDevice(device_);
}

void EmbreeReference::build(EmbreeQuality q) {
  RTCScene& scene = scenes_[static_cast<int>(q)];
  if (scene) rtcReleaseScene(scene);
  scene = rtcNewScene(device_);
  const RTCBuildQuality quality = q == EmbreeQuality::kHigh ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM;
  rtcSetSceneBuildQuality(scene, quality);
  if (robust_) rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geom, quality);
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
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene);
}

int EmbreeReference::scene_flags(EmbreeQuality q) const {
  return static_cast<int>(rtcGetSceneFlags(scenes_[static_cast<int>(q)]));
}

namespace {

/// Calls [first, last) of a batch of width N: closest hits, or any hits (Occluded).
template <bool Occluded, int N>
void calls(RTCScene scene, EmbreeBatch::Impl& b, size_t first, size_t last, RTCIntersectContext* ctx) {
  auto* rh = static_cast<typename Width<N>::RayHit*>(b.live.data);
  for (size_t c = first; c < last; ++c) {
    const int* valid = N == 1 ? nullptr : &b.valid[c * N];
    if constexpr (Occluded) {
      Width<N>::occluded(valid, scene, ctx, &rh[c].ray);
    } else {
      Width<N>::intersect(valid, scene, ctx, &rh[c]);
    }
  }
}

}  // namespace

template <bool Occluded>
void EmbreeReference::trace(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const {
  RTCScene scene = scenes_[static_cast<int>(q)];
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  EmbreeBatch::Impl& b = *batch.impl_;
  // clang-format off
  switch (batch.width()) {
    case 1: calls<Occluded, 1>(scene, b, first, last, &ctx); break;
    case 4: calls<Occluded, 4>(scene, b, first, last, &ctx); break;
    case 8: calls<Occluded, 8>(scene, b, first, last, &ctx); break;
    default: calls<Occluded, 16>(scene, b, first, last, &ctx); break;
  }
  // clang-format on
}

void EmbreeReference::intersect(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const {
  trace<false>(q, batch, first, last, coherent);
}

void EmbreeReference::occluded(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const {
  trace<true>(q, batch, first, last, coherent);
}

void EmbreeReference::hits(const EmbreeBatch& batch, std::vector<uint32_t>& prim) {
  const EmbreeBatch::Impl& b = *batch.impl_;
  prim.assign(b.packets * core::kPacketSize, core::kInvalidId);
  const int w = batch.width();
  for (size_t c = 0; c < batch.calls(); ++c) {
    const auto [p, o] = b.origin[c];
    if (w == 1) {
      const RTCRayHit& h = static_cast<const RTCRayHit*>(b.live.data)[c];
      if (h.hit.geomID != RTC_INVALID_GEOMETRY_ID) prim[p * core::kPacketSize + o] = h.hit.primID;
      continue;
    }
    auto read = [&](const auto* rh) {
      for (int k = 0; k < w; ++k) {
        if (b.valid[c * w + k] && rh[c].hit.geomID[k] != RTC_INVALID_GEOMETRY_ID) prim[p * core::kPacketSize + o + k] = rh[c].hit.primID[k];
      }
    };
    if (w == 4) read(static_cast<const RTCRayHit4*>(b.live.data));
    else if (w == 8) read(static_cast<const RTCRayHit8*>(b.live.data));
    else read(static_cast<const RTCRayHit16*>(b.live.data));
  }
}

void EmbreeReference::blocked(const EmbreeBatch& batch, std::vector<core::LaneMask>& out) {
  const EmbreeBatch::Impl& b = *batch.impl_;
  out.assign(b.packets, 0u);
  const int w = batch.width();
  for (size_t c = 0; c < batch.calls(); ++c) {
    const auto [p, o] = b.origin[c];
    if (w == 1) {
      if (static_cast<const RTCRayHit*>(b.live.data)[c].ray.tfar < 0.0f) out[p] |= 1u << o;
      continue;
    }
    auto read = [&](const auto* rh) {
      for (int k = 0; k < w; ++k) {
        if (b.valid[c * w + k] && rh[c].ray.tfar[k] < 0.0f) out[p] |= 1u << (o + k);
      }
    };
    if (w == 4) read(static_cast<const RTCRayHit4*>(b.live.data));
    else if (w == 8) read(static_cast<const RTCRayHit8*>(b.live.data));
    else read(static_cast<const RTCRayHit16*>(b.live.data));
  }
}

}  // namespace artrace::tools
#endif
