// The real scene as geometry, on synthetic recordings of the demo room with Kinect-like noise
// (where the truth is known exactly): anchors on the floor and the table, the fused room's
// accuracy against the room's own triangles, and stable occlusion where a model touches the floor.
#include "artrace/core/srgb.h"
#include "artrace/ar/compositor.h"
#include "artrace/ar/plane_fit.h"
#include "artrace/io/ar_scene.h"
#include "artrace/io/fusion.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/recording.h"
#include "../cli_util.h"
#include "../test_util.h"

#include <fstream>


namespace artrace::io {
namespace {

constexpr int kW = 320, kH = 240;

/// A synthetic recording of the demo room: `orbit_deg` of camera motion over `frames`, the
/// Kinect-like depth model or exact depth, written as a TUM folder.
std::filesystem::path room_recording(const std::string& name, int frames, double orbit_deg, bool noisy) {
  // Made once a test process (its own scratch folder), then reused by its later calls; written
  // under another name and renamed into place, so a folder under `name` is always complete.
  const auto dir = ::artrace::test::scratch_path(name);
  if (std::filesystem::exists(dir / "rgb.txt")) return dir;
  const auto part = ::artrace::test::scratch_path(name + ".partial");
  std::filesystem::remove_all(part);
  const AffScene room = load_aff(kRoot / "data/scenes/room.aff");
  SynthOptions o;
  o.frames = frames;
  o.width = kW;
  o.height = kH;
  o.orbit_deg = orbit_deg;
  if (noisy) o.depth_model = ar::DepthModel{};
  Synthesizer synth(room, o);
  {
    auto w = make_recording_writer(part);
    synth.write(*w);
  }
  std::filesystem::rename(part, dir);
  return dir;
}

Eigen::Vector3d world_point(const ar::SensorFrame& f, int u, int v, double z) {
  const ar::PinholeIntrinsics& k = f.color_intrinsics;
  return (*f.world_from_camera) * Eigen::Vector3d((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z);
}

/// A pixel of frame `f` (exact depth) whose whole (2r+1)^2 neighbourhood sees the surface `on`,
/// nearest to (u0, v0); false when there is none.
template <class On>
bool find_pixel(const ar::SensorFrame& f, int u0, int v0, int r, const On& on, int& u, int& v) {
  double best = 1e300;
  for (int y = r; y < f.depth.height - r; y += 2) {
    for (int x = r; x < f.depth.width - r; x += 2) {
      bool all = true;
      for (int dy = -r; dy <= r && all; dy += 2)
        for (int dx = -r; dx <= r && all; dx += 2) all = on(world_point(f, x + dx, y + dy, f.depth.at(x + dx, y + dy)));
      const double d = (x - u0) * (x - u0) + (y - v0) * (y - v0);
      if (all && d < best) {
        best = d;
        u = x;
        v = y;
      }
    }
  }
  return best < 1e300;
}

bool on_floor(const Eigen::Vector3d& p) { return std::fabs(p.y()) < 3e-3 && std::fabs(p.x()) < 2.8 && std::fabs(p.z()) < 2.8; }
bool on_table(const Eigen::Vector3d& p) { return std::fabs(p.y() - 0.76) < 3e-3 && std::fabs(p.x()) < 0.75 && std::fabs(p.z()) < 0.55; }

/// A model anchored at a floor pixel and one at a table pixel of a noisy frame sit on those
/// surfaces within 1 cm, their up axes within 1 degree of the surfaces' normals (+y), unmirrored,
/// facing the camera turned by their rotation_deg; a third with an offset rises by it.
TEST(RealScene, AnchorsSitOnTheFloorAndTheTable) {
  const auto noisy = room_recording("artrace_room_noisy_orbit", 20, 30.0, true);
  const auto exact = room_recording("artrace_room_exact_orbit", 20, 30.0, false);
  auto truth = open_recording(exact);
  ar::SensorFrame f;
  ASSERT_TRUE(truth->next(f));
  int fu = 0, fv = 0, tu = 0, tv = 0;
  ASSERT_TRUE(find_pixel(f, kW / 2, kH - 20, 14, on_floor, fu, fv)) << "a floor pixel";
  ASSERT_TRUE(find_pixel(f, kW / 2, kH / 2, 8, on_table, tu, tv)) << "a table pixel";
  const auto dir = noisy.parent_path() / "artrace_anchor_scene";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "scene.json") << R"({ "models": [
      { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string() << R"(", "anchor": { "frame": 0, "pixel": [)" << fu << "," << fv << R"(] } },
      { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string() << R"(", "anchor": { "frame": 0, "pixel": [)" << tu << "," << tv
                                    << R"(], "rotation_deg": 45, "offset": 0.0 } },
      { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string() << R"(", "anchor": { "frame": 0, "pixel": [)" << tu << "," << tv
                                    << R"(], "offset": 0.1 } } ] })";
  ArSceneFile scene = load_ar_scene(dir / "scene.json");
  auto rec = open_recording(noisy);
  resolve_anchors(scene, *rec);
  const glm::vec3 eye(f.world_from_camera->translation().x(), f.world_from_camera->translation().y(), f.world_from_camera->translation().z());
  for (int i = 0; i < 3; ++i) {
    const ArModelPlacement& p = scene.models[static_cast<size_t>(i)];
    ASSERT_TRUE(p.anchored.has_value());
    const glm::mat4 m = p.world_from_model();
    const glm::vec3 origin(m[3]), up = glm::normalize(glm::vec3(m[1]));
    const float height = i == 0 ? 0.0f : i == 1 ? 0.76f : 0.86f;  // the third rises by its offset of 0.1 m
    EXPECT_NEAR(origin.y, height, 0.01f) << (i == 0 ? "floor" : "table");
    // a rotation, not a mirror: +X = +Y x +Z, as the model's own axes are
    EXPECT_GT(glm::determinant(glm::mat3(m)), 0.0f) << "model " << i << " is mirrored";
    // +Z faces the camera along the surface, turned by rotation_deg about the normal (45 for the second)
    glm::vec3 towards = eye - origin;
    towards = glm::normalize(towards - up * glm::dot(up, towards));
    const float turn = glm::degrees(std::acos(std::clamp(glm::dot(glm::normalize(glm::vec3(m[2])), towards), -1.0f, 1.0f)));
    EXPECT_NEAR(turn, i == 1 ? 45.0f : 0.0f, 1.0f) << "model " << i;
    const float angle = glm::degrees(std::acos(std::clamp(up.y, -1.0f, 1.0f)));
    EXPECT_LT(angle, 1.0f) << (i == 0 ? "floor" : "table") << ": up axis " << up.x << "," << up.y << "," << up.z;
    // the origin lies on the ray of the anchor's pixel: where the camera saw the surface
    if (i == 2) continue;  // raised off the surface: not on the pixel's ray
    const Eigen::Vector3d on_ray = world_point(f, i == 0 ? fu : tu, i == 0 ? fv : tv, 1.0) - f.world_from_camera->translation();
    const Eigen::Vector3d to_origin = Eigen::Vector3d(origin.x, origin.y, origin.z) - f.world_from_camera->translation();
    EXPECT_LT(on_ray.normalized().cross(to_origin.normalized()).norm(), 1e-3);
  }
  // a pixel outside the depth image, and one on no plane, are named
  std::ofstream(dir / "bad.json") << R"({ "models": [ { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string()
                                  << R"(", "anchor": { "frame": 0, "pixel": [5000, 10] } } ] })";
  ArSceneFile bad = load_ar_scene(dir / "bad.json");
  try {
    resolve_anchors(bad, *rec);
    ADD_FAILURE() << "accepted";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("models[0].anchor.pixel"), std::string::npos) << e.what();
  }
}

/// Closest point on a triangle (Ericson, "Real-Time Collision Detection", 5.1.5), in double.
glm::dvec3 closest_on_triangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

/// The room fused from 20 noisy frames lies within 1 cm RMS of the room's true triangles (every
/// 50th vertex, its distance to the nearest triangle, by brute force).
TEST(RealScene, FusedRoomLiesWithinOneCentimetreOfTheTrueSurfaces) {
  const auto noisy = room_recording("artrace_room_noisy_orbit", 20, 30.0, true);
  auto rec = open_recording(noisy);
  FusionOptions o;
  o.max_depth_m = 4.0;
  FusionStats st;
  const ar::RoomMesh mesh = fuse_recording(*rec, o, &st);
  EXPECT_EQ(st.frames, 20);
  ASSERT_GT(mesh.triangles.size(), 1000u);
  const std::vector<core::Triangle> truth = load_aff(kRoot / "data/scenes/room.aff").triangles_at(1.0);
  double ss = 0.0;
  int n = 0, far = 0;
  for (size_t i = 0; i < mesh.positions.size(); i += 50) {
    const glm::dvec3 p(mesh.positions[i]);
    double best = 1e300;
    for (const core::Triangle& t : truth) best = std::min(best, glm::length(p - closest_on_triangle(p, glm::dvec3(t.v0), glm::dvec3(t.v1), glm::dvec3(t.v2))));
    ss += best * best;
    far += best > 0.05;
    ++n;
  }
  const double rms = std::sqrt(ss / n);
  EXPECT_LT(rms, 0.01) << "over " << n << " vertices, " << far << " more than 5 cm off";
  // the mesh written as PLY and read back by Open3D: every vertex to the bit, every triangle, and
  // each colour as its 8-bit sRGB value gives it
  const auto ply = noisy.parent_path() / "artrace_room.ply";
  write_room_ply(mesh, ply);
  const ar::RoomMesh back = read_room_ply(ply);
  ASSERT_EQ(back.triangles.size(), mesh.triangles.size());
  ASSERT_EQ(back.positions.size(), mesh.positions.size());
  ASSERT_EQ(back.colours.size(), mesh.colours.size());
  EXPECT_TRUE(back.positions == mesh.positions);
  EXPECT_TRUE(back.triangles == mesh.triangles);
  size_t colours_off = 0;
  for (size_t i = 0; i < mesh.colours.size(); ++i) {
    for (int k = 0; k < 3; ++k) colours_off += back.colours[i][k] != core::srgb8_to_linear(core::linear_to_srgb8(mesh.colours[i][k]));
  }
  EXPECT_EQ(colours_off, 0u);
}

struct ContactFigures {
  double flips = 0.0;       ///< mean share of the model's pixels whose visibility changed from the frame before
  double contact_iou = 1.0;  ///< worst frame, near the contact, against the exact depth's mask
};

/// A model on the floor, seen by a fixed camera through 12 noisy frames: how its visibility
/// flickers, and how the mask near the floor compares with the one from exact depth.
ContactFigures contact(const ArSceneFile& scene, const std::vector<ar::SensorFrame>& noisy, const std::vector<ar::SensorFrame>& exact,
                       bool planes, const ar::FusedRoom* room) {
  ArRuntime rt(scene);
  ar::CompositeOptions o;
  o.lights = {{{1.5f, 2.8f, 1.0f}, glm::vec3(1.0f)}};
  o.shadows = false;
  o.keep_visibility = true;
  o.threads = 2;
  o.room = room;
  if (planes) o.support_planes = {*scene.models[0].support};
  const auto lookup = [&](const ar::SurfaceQuery& q) { return rt.material(q); };
  ContactFigures out;
  std::vector<uint8_t> prev;
  double flip_sum = 0.0;
  for (size_t k = 0; k < noisy.size(); ++k) {
    ar::CompositeStats st;
    ar::composite(noisy[k], rt.scene(), lookup, o, &st);
    const std::vector<uint8_t> truth = ar::exact_visibility(exact[k].depth, st.virtual_depth);
    std::vector<uint8_t> vis(st.visibility.size());
    int model = 0, inter = 0, uni = 0;
    for (size_t i = 0; i < vis.size(); ++i) {
      vis[i] = st.visibility[i] >= 0.5f;
      if (!std::isfinite(st.virtual_depth[i])) continue;
      ++model;
      // near the contact: the virtual surface within 5 cm of the floor
      const int u = static_cast<int>(i % kW), v = static_cast<int>(i / kW);
      if (world_point(noisy[k], u, v, st.virtual_depth[i]).y() < 0.05) {
        inter += vis[i] && truth[i];
        uni += vis[i] || truth[i];
      }
    }
    if (uni > 0) out.contact_iou = std::min(out.contact_iou, static_cast<double>(inter) / uni);
    if (!prev.empty()) {
      int flips = 0;
      for (size_t i = 0; i < vis.size(); ++i) flips += std::isfinite(st.virtual_depth[i]) && vis[i] != prev[i];
      flip_sum += static_cast<double>(flips) / std::max(1, model);
    }
    prev = vis;
  }
  out.flips = flip_sum / static_cast<double>(noisy.size() - 1);
  return out;
}

/// Where a model touches the floor, occlusion does not shred: a 40 x 40 cm mat 5 mm thin lying on
/// the floor (all of it contact, within the sensor's noise and disparity steps of the floor at 3 m).
/// With the anchor's fitted plane, or with the fused room, fewer than 1% of its pixels flip between
/// frames and the mask has IoU >= 0.99 against the one from exact depth. The raw noisy depth,
/// measured the same way, flickers more: the reason for both.
TEST(RealScene, ContactsStayStableWithTheFittedPlaneOrTheFusedRoom) {
  const auto noisy_dir = room_recording("artrace_room_noisy_still", 12, 0.0, true);
  const auto exact_dir = room_recording("artrace_room_exact_still", 12, 0.0, false);
  std::vector<ar::SensorFrame> noisy, exact;
  for (auto [dir, out] : {std::pair{noisy_dir, &noisy}, std::pair{exact_dir, &exact}}) {
    auto r = open_recording(dir);
    for (ar::SensorFrame f; r->next(f);) out->push_back(f);
  }
  ASSERT_EQ(noisy.size(), 12u);
  int fu = 0, fv = 0;
  ASSERT_TRUE(find_pixel(exact[0], kW / 2 - 40, kH - 40, 14, on_floor, fu, fv));
  const auto dir = noisy_dir.parent_path() / "artrace_contact_scene";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "scene.json") << R"({ "models": [ { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string()
                                    << R"(", "scale": [2.0, 0.025, 2.0], "anchor": { "frame": 0, "pixel": [)" << fu << "," << fv << R"(] } } ] })";
  ArSceneFile scene = load_ar_scene(dir / "scene.json");
  auto rec = open_recording(noisy_dir);
  resolve_anchors(scene, *rec);
  rec->rewind();
  const ar::FusedRoom room(fuse_recording(*rec, FusionOptions{}));
  const ContactFigures raw = contact(scene, noisy, exact, false, nullptr);
  const ContactFigures plane = contact(scene, noisy, exact, true, nullptr);
  const ContactFigures fused = contact(scene, noisy, exact, false, &room);
  std::printf("contact flips: raw %.4f, plane %.4f, fused %.4f; contact IoU raw %.4f, plane %.4f, fused %.4f\n", raw.flips, plane.flips,
              fused.flips, raw.contact_iou, plane.contact_iou, fused.contact_iou);
  EXPECT_LT(plane.flips, 0.01);
  EXPECT_LT(fused.flips, 0.01);
  EXPECT_GE(plane.contact_iou, 0.99);
  EXPECT_GE(fused.contact_iou, 0.99);
  EXPECT_GT(raw.flips, plane.flips) << "the raw depth should flicker more";
}

/// Every plane `info --planes` lists on a real frame is the plane an anchor at its listed pixel
/// stands on: the fit around the pixel agrees with the listed plane (normal within 5 degrees,
/// the pixel's point within 2 cm of it). On the tabletop recording the listed shelf pixel once
/// gave a plane tilted by the shelf's front edge, and a model anchored there leant over.
TEST(RealScene, ListedPlanesAreThePlanesAnchorsAtTheirPixelsStandOn) {
  ARTRACE_REQUIRE_SHARED("rgbd");
  for (const char* rec : {"rgbd/oni-kinect1-tabletop-4f/Captured.oni", "rgbd/tum-fr1-rpy"}) {
    const auto source = open_recording(shared_path.parent_path() / rec);
    ar::SensorFrame f;
    ASSERT_TRUE(source->next(f)) << rec;
    const std::vector<ar::Plane> planes = ar::detect_planes(f);
    ASSERT_FALSE(planes.empty()) << rec;
    for (const ar::Plane& p : planes) {
      const std::optional<ar::Plane> at = ar::plane_at_pixel(f, p.pixel_u, p.pixel_v);
      ASSERT_TRUE(at.has_value()) << rec << ": no plane at the listed pixel (" << p.pixel_u << ", " << p.pixel_v << ")";
      const double deg = std::acos(std::clamp(at->normal.dot(p.normal), -1.0, 1.0)) * 180.0 / M_PI;
      EXPECT_LT(deg, 5.0) << rec << ": pixel (" << p.pixel_u << ", " << p.pixel_v << ")";
      EXPECT_LT(std::fabs(p.distance(at->point)), 0.02) << rec << ": pixel (" << p.pixel_u << ", " << p.pixel_v << ")";
    }
  }
}

}  // namespace
}  // namespace artrace::io
