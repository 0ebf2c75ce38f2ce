// The virtual objects' effect on the real scene, against geometry worked out independently: the
// shadow a virtual box casts on a real wall (differential rendering: where, and how dark), and a
// virtual mirror showing the recorded wall through the depth mesh.
#include "artrace/ar/compositor.h"
#include "artrace/ar/real_scene.h"
#include "artrace/core/srgb.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>

namespace artrace::ar {
namespace {

constexpr int kW = 160, kH = 120;
constexpr double kF = 120.0, kCx = 79.5, kCy = 59.5;

/// A wall at 2 m facing the camera (identity pose), with a colour gradient.
SensorFrame wall_frame() {
  SensorFrame f;
  f.color.width = f.depth.width = kW;
  f.color.height = f.depth.height = kH;
  f.color.rgb.resize(3 * kW * kH);
  f.depth.depth_m.assign(kW * kH, 2.0f);
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      uint8_t* p = f.color.rgb.data() + 3 * (y * kW + x);
      p[0] = static_cast<uint8_t>(40 + x);
      p[1] = static_cast<uint8_t>(60 + y);
      p[2] = 150;
    }
  }
  f.color_intrinsics = f.depth_intrinsics = PinholeIntrinsics{kW, kH, kF, kF, kCx, kCy};
  f.world_from_camera = Eigen::Isometry3d::Identity();
  return f;
}

glm::vec3 wall_point(int x, int y) {
  return {static_cast<float>((x - kCx) / kF * 2.0), static_cast<float>((y - kCy) / kF * 2.0), 2.0f};
}

std::vector<core::Triangle> box(glm::vec3 lo, glm::vec3 hi) {
  std::vector<core::Triangle> t;
  auto c = [&](int i) { return glm::vec3((i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z); };
  const int faces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  for (const auto& f : faces) {
    t.push_back({c(f[0]), c(f[1]), c(f[2])});
    t.push_back({c(f[0]), c(f[2]), c(f[3])});
  }
  return t;
}

/// Segment p -> q against a box, in double precision (independent of the renderer's code).
bool segment_hits_box(glm::dvec3 p, glm::dvec3 q, glm::dvec3 lo, glm::dvec3 hi) {
  double t0 = 0.0, t1 = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double d = q[a] - p[a];
    if (std::fabs(d) < 1e-15) {
      if (p[a] < lo[a] || p[a] > hi[a]) return false;
      continue;
    }
    double n = (lo[a] - p[a]) / d, f = (hi[a] - p[a]) / d;
    if (n > f) std::swap(n, f);
    t0 = std::max(t0, n);
    t1 = std::min(t1, f);
  }
  return t0 <= t1;
}

/// The shadow tests' box, its light, and their options: ambient 0.3, that light, 2 threads.
const glm::vec3 kBoxLo(0.05f, -0.25f, 1.3f), kBoxHi(0.25f, -0.05f, 1.5f);
const VirtualLight kLight{{-0.4f, -0.5f, 0.3f}, {0.9f, 0.8f, 0.7f}};

CompositeOptions shadow_options() {
  CompositeOptions opt;
  opt.ambient = 0.3f;
  opt.lights = {kLight};
  opt.threads = 2;
  return opt;
}

/// The wall pixels of `out` against the analytic shadow of the box [box_lo, box_hi] from `light`: away
/// from the shadow's edge (where either answer is right) and from the box itself, a pixel outside
/// the shadow keeps its recorded colour, and one inside is scaled, by differential rendering, by
/// (ambient + light cos passing) / (ambient + light cos), `passing` the light the box lets through.
/// `real_shadow`, where given, tells the wall points a real surface already shadows from the light:
/// the box adds nothing there. Pixels next to a depth other than the wall's are not checked.
struct WallShadow {
  int in_shadow = 0, wrong = 0, boundary = 0;  ///< wrong: darkened outside the shadow, or not inside
  int shadowed_already = 0;                    ///< in the box's shadow, but a real surface's already
};
WallShadow check_wall_shadow(const SensorFrame& frame, const ColorImage& out, const core::TwoLevelScene& scene,
                             float passing, const VirtualLight& light = kLight,
                             const std::function<bool(int, int)>& real_shadow = nullptr, const glm::vec3& box_lo = kBoxLo,
                             const glm::vec3& box_hi = kBoxHi) {
  const float ambient = shadow_options().ambient;
  WallShadow r;
  auto in_box_shadow = [&](int x, int y) {
    return segment_hits_box(glm::dvec3(wall_point(x, y)), glm::dvec3(light.position), glm::dvec3(box_lo), glm::dvec3(box_hi));
  };
  auto already = [&](int x, int y) { return real_shadow && real_shadow(x, y); };
  auto shadowed = [&](int x, int y) { return in_box_shadow(x, y) && !already(x, y); };
  auto on_wall = [&](int x, int y) {
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if (frame.depth.at(x + dx, y + dy) != 2.0f) return false;
    return true;
  };
  // within 2 px of the image's edge the compositor knows no normal (it takes the depth map's from
  // neighbours 2 px away) and so no cosine: those pixels are not checked
  for (int y = 2; y + 2 < kH; ++y) {
    for (int x = 2; x + 2 < kW; ++x) {
      // pixels where the box itself is seen are the compositor's business, not this check's
      const glm::vec3 w = wall_point(x, y);
      if (!on_wall(x, y) || scene.intersect(core::Ray{glm::vec3(0.0f), w, 0.0f, 1.0f}).valid()) continue;
      if (already(x, y) != already(x - 1, y) || already(x, y) != already(x + 1, y) || already(x, y) != already(x, y - 1) ||
          already(x, y) != already(x, y + 1)) {
        ++r.boundary;
        continue;
      }
      r.shadowed_already += in_box_shadow(x, y) && already(x, y);
      const bool s = shadowed(x, y);
      if (s != shadowed(x - 1, y) || s != shadowed(x + 1, y) || s != shadowed(x, y - 1) || s != shadowed(x, y + 1)) {
        ++r.boundary;
        continue;
      }
      const uint8_t* in = frame.color.at(x, y);
      const uint8_t* o = out.at(x, y);
      const bool darkened = in[0] != o[0] || in[1] != o[1] || in[2] != o[2];
      r.in_shadow += s;
      if (s != darkened) {
        ++r.wrong;
        continue;
      }
      if (!s) continue;
      const float cosine = glm::normalize(light.position - w).z * -1.0f;
      for (int c = 0; c < 3; ++c) {
        const float factor = (ambient + light.color[c] * cosine * passing) / (ambient + light.color[c] * cosine);
        const int expected = core::linear_to_srgb8(core::srgb8_to_linear(in[c]) * factor);
        EXPECT_NEAR(o[c], expected, 1) << x << "," << y << " channel " << c;
      }
    }
  }
  return r;
}

TEST(Compositor, VirtualBoxCastsItsShadowOnTheRealWall) {
  const SensorFrame frame = wall_frame();
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  scene.add_instance(scene.add_rigid_mesh(box(kBoxLo, kBoxHi)), glm::mat4(1.0f));
  scene.commit();
  CompositeOptions opt = shadow_options();
  const MaterialLookup diffuse = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  CompositeStats st;
  const ColorImage out = composite(frame, scene, diffuse, opt, &st);

  const WallShadow check = check_wall_shadow(frame, out, scene, 0.0f);
  EXPECT_GT(check.in_shadow, 200) << "the shadow is on the wall";
  EXPECT_EQ(check.wrong, 0) << "pixels darkened outside the analytic shadow, or left lit inside it";
  EXPECT_LT(check.boundary, check.in_shadow / 2);
  EXPECT_GT(st.shadowed_real_pixels, 200);
  // and without shadows on real surfaces, the wall is untouched outside the box
  opt.real_shadows = false;
  const ColorImage plain = composite(frame, scene, diffuse, opt);
  const glm::vec3 centre_of_shadow = [&] {
    glm::dvec3 sum(0.0);
    int n = 0;
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) {
        if (segment_hits_box(glm::dvec3(wall_point(x, y)), glm::dvec3(kLight.position), glm::dvec3(kBoxLo), glm::dvec3(kBoxHi))) {
          sum += glm::dvec3(x, y, 0);
          ++n;
        }
      }
    }
    return glm::vec3(sum / static_cast<double>(n));
  }();
  const int cx = static_cast<int>(centre_of_shadow.x), cy = static_cast<int>(centre_of_shadow.y);
  EXPECT_EQ(plain.at(cx, cy)[0], frame.color.at(cx, cy)[0]);
  EXPECT_LT(out.at(cx, cy)[0], frame.color.at(cx, cy)[0]);
}

/// A virtual object reaching almost to the camera plane far to the side projects billions of
/// pixels off screen, and so do the vanishing points of a shadow volume lit from beside the camera.
/// The screen rectangles (objects traced, real points shadowed) must then cover the screen; they
/// used to come out empty (a float beyond int converted to int), which left out the box and its
/// shadow. Here: a sliver triangle 100 km wide, 50 m below the camera and 2-3 mm in front of it
/// (out of sight of the wall and of the light's rays to it), and the light 1.5 mm in front of it.
/// A real board 1 m from the camera, between the wall and the light, shadows part of the wall
/// already: the recording shows that shadow, so where the box's shadow falls on it the box changes
/// nothing; elsewhere the box darkens the wall as before. The board's shadow is worked out
/// independently: a wall point's segment to the light crosses the plane z = 1 inside the board's
/// rectangle (the board's pixels' centres, back-projected).
TEST(Compositor, AVirtualShadowAddsNothingWhereARealSurfaceShadowsAlready) {
  SensorFrame frame = wall_frame();
  constexpr int bx0 = 40, bx1 = 74, by0 = 8, by1 = 42;
  for (int y = by0; y < by1; ++y)
    for (int x = bx0; x < bx1; ++x) frame.depth.depth_m[static_cast<size_t>(y) * kW + x] = 1.0f;
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kKdTreeBvh);
  scene.set_static(box(kBoxLo, kBoxHi));
  scene.commit();
  const MaterialLookup material = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  CompositeStats st;
  const ColorImage out = composite(frame, scene, material, shadow_options(), &st);
  const glm::dvec3 l(kLight.position);
  const auto board = [&](int x, int y) {
    const glm::dvec3 w(wall_point(x, y));
    const glm::dvec3 q = w + (2.0 - 1.0) / (2.0 - l.z) * (l - w);  // on the plane z = 1
    return q.x >= (bx0 - kCx) / kF && q.x <= (bx1 - 1 - kCx) / kF && q.y >= (by0 - kCy) / kF && q.y <= (by1 - 1 - kCy) / kF;
  };
  const WallShadow r = check_wall_shadow(frame, out, scene, 0.0f, kLight, board);
  EXPECT_GT(r.in_shadow, 100);
  EXPECT_GT(r.shadowed_already, 100) << "the board should take part of the box's shadow";
  EXPECT_EQ(r.wrong, 0);
}

TEST(Compositor, ObjectsProjectingFarOffScreenKeepTheirPixelsAndShadows) {
  const SensorFrame frame = wall_frame();
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  scene.add_instance(scene.add_rigid_mesh(box(kBoxLo, kBoxHi)), glm::mat4(1.0f));
  const std::vector<core::Triangle> ground{{{-5e4f, 50.0f, 0.002f}, {5e4f, 50.0f, 0.002f}, {0.0f, 50.1f, 0.003f}}};
  scene.add_instance(scene.add_rigid_mesh(ground), glm::mat4(1.0f));
  scene.commit();
  const VirtualLight light{{0.0f, -0.5f, 0.0015f}, {0.9f, 0.8f, 0.7f}};
  CompositeOptions opt = shadow_options();
  opt.lights = {light};
  const MaterialLookup diffuse = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  const ColorImage out = composite(frame, scene, diffuse, opt);

  // the box is drawn where it is seen: its centre's pixel is no longer the wall's
  const glm::vec3 centre = 0.5f * (kBoxLo + kBoxHi);
  const int bx = static_cast<int>(kCx + kF * centre.x / centre.z + 0.5), by = static_cast<int>(kCy + kF * centre.y / centre.z + 0.5);
  const uint8_t* seen = out.at(bx, by);
  const uint8_t* wall = frame.color.at(bx, by);
  EXPECT_TRUE(seen[0] != wall[0] || seen[1] != wall[1] || seen[2] != wall[2]) << "the box is not drawn";
  const WallShadow check = check_wall_shadow(frame, out, scene, 0.0f, light);
  EXPECT_GT(check.in_shadow, 200) << "the shadow is on the wall";
  EXPECT_EQ(check.wrong, 0) << "pixels darkened outside the analytic shadow, or left lit inside it";
}

/// A box reaching from behind the camera to in front of the wall (seen in the image's top right),
/// lit from behind the camera: it is drawn on every pixel whose ray meets it (brute force, in
/// double precision) and its shadow falls on the wall as worked out, but only what of it and its
/// shadow volume lies in front of the camera is traced and shadow-tested, not the whole image.
TEST(Compositor, ObjectsReachingBehindTheCameraAreTracedWhereTheyAreSeen) {
  const SensorFrame frame = wall_frame();
  const glm::vec3 lo(0.3f, -0.3f, -0.6f), hi(0.5f, -0.1f, 1.5f);
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  scene.add_instance(scene.add_rigid_mesh(box(lo, hi)), glm::mat4(1.0f));
  scene.commit();
  const VirtualLight light{{0.0f, 0.5f, -1.0f}, {0.9f, 0.8f, 0.7f}};
  CompositeOptions opt = shadow_options();
  opt.lights = {light};
  const MaterialLookup diffuse = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  CompositeStats st;
  const ColorImage out = composite(frame, scene, diffuse, opt, &st);

  auto seen = [&](int x, int y) { return segment_hits_box(glm::dvec3(0.0), glm::dvec3(wall_point(x, y)), glm::dvec3(lo), glm::dvec3(hi)); };
  int inside = 0, missing = 0;
  for (int y = 1; y + 1 < kH; ++y) {
    for (int x = 1; x + 1 < kW; ++x) {
      if (!seen(x, y) || !seen(x - 1, y) || !seen(x + 1, y) || !seen(x, y - 1) || !seen(x, y + 1)) continue;
      ++inside;
      const uint8_t* o = out.at(x, y);
      const uint8_t* in = frame.color.at(x, y);
      missing += o[0] == in[0] && o[1] == in[1] && o[2] == in[2];
    }
  }
  EXPECT_GT(inside, 300) << "the box is seen in the image";
  EXPECT_EQ(missing, 0) << "pixels where the box is seen keep the wall's colour";
  EXPECT_LT(st.traced_pixels, kW * kH / 2) << "the whole image traced for a box seen in its corner";

  const WallShadow check = check_wall_shadow(frame, out, scene, 0.0f, light, nullptr, lo, hi);
  EXPECT_GT(check.in_shadow, 200) << "the shadow is on the wall";
  EXPECT_EQ(check.wrong, 0) << "pixels darkened outside the analytic shadow, or left lit inside it";
  EXPECT_GT(st.shadow_area_pixels, 0);
  EXPECT_LT(st.shadow_area_pixels, kW * kH) << "the whole image tested for the shadow of a volume bounded in front of the camera";
}

/// A box wholly behind the camera and beside its axis, lit from further behind: nothing of it is
/// traced, but its shadow volume reaches forward past the camera onto the wall's right part, and the
/// shadow is there; the pixels tested for it are not the whole image.
TEST(Compositor, ABoxBehindTheCameraShadowsTheWallInFront) {
  const SensorFrame frame = wall_frame();
  const glm::vec3 lo(0.3f, -0.1f, -0.5f), hi(0.5f, 0.1f, -0.3f);
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  scene.add_instance(scene.add_rigid_mesh(box(lo, hi)), glm::mat4(1.0f));
  scene.commit();
  const VirtualLight light{{0.2f, 0.05f, -1.5f}, {0.9f, 0.8f, 0.7f}};
  CompositeOptions opt = shadow_options();
  opt.lights = {light};
  const MaterialLookup diffuse = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  CompositeStats st;
  const ColorImage out = composite(frame, scene, diffuse, opt, &st);
  EXPECT_EQ(st.traced_pixels, 0) << "nothing of the box is in front of the camera";
  const WallShadow check = check_wall_shadow(frame, out, scene, 0.0f, light, nullptr, lo, hi);
  EXPECT_GT(check.in_shadow, 1000) << "the shadow is on the wall";
  EXPECT_EQ(check.wrong, 0) << "pixels darkened outside the analytic shadow, or left lit inside it";
  EXPECT_LT(st.shadow_area_pixels, kW * kH);
}

/// A grey rectangle [x0, x1] x [y0, y1] at depth z, two triangles, added to a room mesh.
void room_quad(RoomMesh& m, float x0, float y0, float x1, float y1, float z) {
  const uint32_t b = static_cast<uint32_t>(m.positions.size());
  for (const glm::vec3& p : {glm::vec3(x0, y0, z), glm::vec3(x1, y0, z), glm::vec3(x1, y1, z), glm::vec3(x0, y1, z)}) {
    m.positions.push_back(p);
    m.colours.push_back(glm::vec3(0.5f));
  }
  m.triangles.push_back({b, b + 1, b + 2});
  m.triangles.push_back({b, b + 2, b + 3});
}

/// The fused room cleaning the sensor's depth, against depths worked out by hand. The room: a wall
/// at 2.01 m and, over the image's top half, a panel at 1 m in front of it (a chair since moved
/// away: the sensor sees the wall through it). Columns of readings: 2.0 m (within the noise of the
/// wall: the wall's 2.01 is taken, through the panel too), just within the noise of the wall from
/// the near side (taken), 1.5 m (something the room does not hold: kept), and none (the room's
/// nearest surface: the panel in the top half, the wall below).
TEST(Compositor, TheFusedRoomStandsInWhereTheSensorSawItsSurface) {
  RoomMesh mesh;
  room_quad(mesh, -5.0f, -5.0f, 5.0f, 5.0f, 2.01f);
  room_quad(mesh, -5.0f, -5.0f, 5.0f, -0.001f, 1.0f);  // camera y down: the image's top half
  const FusedRoom room(std::move(mesh));
  // Nguyen et al.'s sigma, three of them, and the disparity step 0.4 % of z^2 a metre
  auto tolerance = [](double z) { return 3.0 * (0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)) + 0.004 * z * z; };
  const float near_edge = static_cast<float>(2.01 - 0.99 * tolerance(2.01));
  SensorFrame frame = wall_frame();
  const float reading[4] = {2.0f, near_edge, 1.5f, 0.0f};
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) frame.depth.depth_m[static_cast<size_t>(y) * kW + x] = reading[x * 4 / kW];
  CompositeOptions opt;
  opt.room = &room;
  opt.threads = 2;
  std::vector<glm::vec3> normals;
  const DepthImage clean = clean_depth(frame, opt, 0, 0, kW, kH, &normals);
  int wrong = 0;
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const int column = x * 4 / kW;
      const bool top = y < kCy;  // rows whose rays meet the panel (y - cy < 0: above the axis)
      float expected = reading[column];
      if (column < 2) expected = 2.01f;
      if (column == 3) expected = top ? 1.0f : 2.01f;
      const size_t i = static_cast<size_t>(y) * kW + x;
      const bool from_room = column != 2;
      const bool ok = std::fabs(clean.depth_m[i] - expected) < 1e-5f &&
                      (from_room ? glm::length(normals[i] - glm::vec3(0.0f, 0.0f, -1.0f)) < 1e-5f : normals[i] == glm::vec3(0.0f));
      if (!ok && wrong++ < 5) ADD_FAILURE() << x << "," << y << ": depth " << clean.depth_m[i] << ", expected " << expected;
    }
  }
  EXPECT_EQ(wrong, 0);
}

/// The compositor cleans the sensor's depth with the fused room only around the objects; the
/// hole filling there reads neighbours up to its reach outside their rectangle, which must have
/// been cleaned too. The oracle: the same composite from the depth cleaned over the whole image
/// (clean_depth) with no room. The sensor reads 2.03 m everywhere, within the noise of the room's
/// wall at 2.0 m, except a patch of holes (6 x 10, 12 x 5 or 12 x 12 pixels, the last with a
/// larger fillable hole) where the room has a slit too (nothing to stand in). The holes are filled
/// from their neighbours pass by pass, from all sides of the patch, the far depth winning where
/// they meet: uncleaned neighbours (2.03) reach into the rectangle as far as the passes go. A thin
/// box 2.01 m away covers the middle of the image: where the filled depth is 2.0 the wall hides it
/// (mostly), where it is 2.03 it shows. The patch is put at each position around the box's left edge in turn, so that its
/// neighbours straddle the edge of the box's screen rectangle.
TEST(Compositor, CleaningAroundTheObjectsGivesTheWholeImageCleaningsPicture) {
  const float z_wall = 2.0f;
  const glm::vec3 lo((60.5f - static_cast<float>(kCx)) / static_cast<float>(kF) * 2.01f,
                     (40.5f - static_cast<float>(kCy)) / static_cast<float>(kF) * 2.01f, 2.01f);
  const glm::vec3 hi((100.5f - static_cast<float>(kCx)) / static_cast<float>(kF) * 2.01f,
                     (80.5f - static_cast<float>(kCy)) / static_cast<float>(kF) * 2.01f, 2.02f);
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  scene.add_instance(scene.add_rigid_mesh(box(lo, hi)), glm::mat4(1.0f));
  scene.commit();
  const MaterialLookup diffuse = [](const core::Hit&) {
    return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f};
  };
  int differing_inside = 0;
  // patches of 6 x 10 and 12 x 5 pixels (at most 64: holes small enough to fill by default), and
  // 12 x 12 with a larger fillable hole, so that the far side's depth travels all passes in
  for (int patch = 0; patch < 3; ++patch) {
    for (int column = 52; column <= 70; ++column) {
      const int width = patch == 0 ? 6 : 12;
      const int row0 = 50, row1 = row0 + (patch == 2 ? 12 : 60 / width);
      const int col0 = column - width / 2, col1 = col0 + width;  // the holes' columns
      // the room: the wall with a slit around the rays of the holes' pixel centres
      // (pixel centres at whole coordinates, as in the intrinsics)
      const float pixel = z_wall / static_cast<float>(kF);  // a pixel's width on the wall
      const float sx0 = (static_cast<float>(col0) - 0.5f - static_cast<float>(kCx)) * pixel;
      const float sx1 = (static_cast<float>(col1) - 0.5f - static_cast<float>(kCx)) * pixel;
      const float sy0 = (static_cast<float>(row0) - 0.5f - static_cast<float>(kCy)) * pixel;
      const float sy1 = (static_cast<float>(row1) - 0.5f - static_cast<float>(kCy)) * pixel;
      RoomMesh mesh;
      room_quad(mesh, -5.0f, -5.0f, sx0, 5.0f, z_wall);
      room_quad(mesh, sx1, -5.0f, 5.0f, 5.0f, z_wall);
      room_quad(mesh, sx0, -5.0f, sx1, sy0, z_wall);
      room_quad(mesh, sx0, sy1, sx1, 5.0f, z_wall);
      const FusedRoom room(std::move(mesh));

      SensorFrame frame = wall_frame();
      std::fill(frame.depth.depth_m.begin(), frame.depth.depth_m.end(), 2.03f);
      for (int y = row0; y < row1; ++y) {
        for (int x = col0; x < col1; ++x) frame.depth.depth_m[static_cast<size_t>(y) * kW + x] = 0.0f;
      }
      CompositeOptions opt;
      opt.shadows = false;
      opt.room = &room;
      opt.threads = 2;
      opt.keep_visibility = true;
      if (patch == 2) opt.occlusion_options.max_hole_px = 144;
      CompositeStats got_stats;
      const ColorImage got = composite(frame, scene, diffuse, opt, &got_stats);

      // the oracle: the depth cleaned over the whole image, composited without the room
      SensorFrame cleaned = frame;
      cleaned.depth = clean_depth(frame, opt, 0, 0, kW, kH);
      ASSERT_EQ(cleaned.depth.depth_m[static_cast<size_t>(row0) * kW + col0], 0.0f) << "the slit leaves the holes";
      ASSERT_EQ(cleaned.depth.depth_m[static_cast<size_t>(row1 - 1) * kW + col1 - 1], 0.0f)
          << "the slit leaves the holes";
      ASSERT_EQ(cleaned.depth.depth_m[static_cast<size_t>(row0) * kW + col0 - 1], z_wall) << "the wall stands in";
      ASSERT_EQ(cleaned.depth.depth_m[static_cast<size_t>(row1) * kW + col0], z_wall) << "the wall stands in";
      CompositeOptions whole = opt;
      whole.room = nullptr;
      CompositeStats want_stats;
      const ColorImage want = composite(cleaned, scene, diffuse, whole, &want_stats);
      EXPECT_TRUE(got.rgb == want.rgb) << "patch " << width << " wide at column " << col0
                                       << ": the picture differs from the whole image cleaning's";
      EXPECT_TRUE(got_stats.visibility == want_stats.visibility) << "patch " << width << " wide at column " << col0;

      // the depth cleaned over about the box's screen rectangle (its pixels and one around) with
      // no margin gives another picture at some column: the scene can tell a missing margin
      SensorFrame inside = frame;
      inside.depth = clean_depth(frame, opt, 59, 39, 102, 82);
      differing_inside += composite(inside, scene, diffuse, whole).rgb != want.rgb;
    }
  }
  EXPECT_GT(differing_inside, 0) << "cleaning without a margin gives the same pictures: the scene tests nothing";
}

/// An object whose shadow volume projects wholly beside the image (its rows overlap the image's, its
/// columns lie left of it) changes nothing on screen. Its screen rectangle is then empty in width
/// only; the real points' test against it once read past its (empty) row spans and crashed.
TEST(Compositor, AShadowVolumeBesideTheImageChangesNothing) {
  const SensorFrame frame = wall_frame();
  const glm::vec3 far_lo(-20.0f, -0.25f, 1.3f), far_hi(-19.8f, -0.05f, 1.5f);
  const MaterialLookup diffuse = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f), 1.5f}; };
  auto render = [&](bool with_far) {
    core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
    scene.add_instance(scene.add_rigid_mesh(box(kBoxLo, kBoxHi)), glm::mat4(1.0f));
    if (with_far) scene.add_instance(scene.add_rigid_mesh(box(far_lo, far_hi)), glm::mat4(1.0f));
    scene.commit();
    CompositeOptions opt = shadow_options();
    opt.object_bounds = {core::Aabb{kBoxLo, kBoxHi}};
    if (with_far) opt.object_bounds.push_back(core::Aabb{far_lo, far_hi});
    return composite(frame, scene, diffuse, opt);
  };
  const ColorImage one = render(false), two = render(true);
  EXPECT_TRUE(one.rgb == two.rgb) << "the object beside the image changed the picture";
}

/// A glass box given its triangles' transmittance darkens the wall where the opaque box would,
/// but only by the light its two faces on the way (in and out) hold back: T^2 of the light passes.
TEST(Compositor, GlassBoxCastsALighterShadowOnTheRealWall) {
  const SensorFrame frame = wall_frame();
  const VirtualMaterial glass{VirtualMaterial::kGlass, glm::vec3(0.9f, 0.8f, 0.7f), 1.5f};
  const float t = shadow_transmittance(glass);
  ASSERT_NEAR(t, (1.0f - 0.04f) * 0.8f, 1e-6f) << "Fresnel at normal incidence, mean tint";
  EXPECT_EQ(shadow_transmittance(VirtualMaterial{}), 0.0f) << "diffuse lets nothing through";
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  const auto tris = box(kBoxLo, kBoxHi);
  const core::MeshHandle mesh = scene.add_rigid_mesh(tris);
  scene.set_mesh_transmittance(mesh, std::vector<float>(tris.size(), t));
  scene.add_instance(mesh, glm::mat4(1.0f));
  scene.commit();
  const ColorImage out = composite(frame, scene, [&](const core::Hit&) { return glass; }, shadow_options());

  const WallShadow check = check_wall_shadow(frame, out, scene, t * t);
  EXPECT_GT(check.in_shadow, 200) << "the shadow is on the wall";
  EXPECT_EQ(check.wrong, 0) << "pixels darkened outside the analytic shadow, or left lit inside it";
}

TEST(Compositor, VirtualMirrorShowsTheRecordedWallThroughTheDepthMesh) {
  const SensorFrame frame = wall_frame();
  // a mirror in the plane x = 0.25 facing the optical axis, from 0.8 m to 1.9 m away
  core::TwoLevelScene scene(core::TwoLevelScene::Config::kBvh);
  const glm::vec3 a(0.25f, -0.3f, 0.8f), b(0.25f, 0.3f, 0.8f), c(0.25f, 0.3f, 1.9f), d(0.25f, -0.3f, 1.9f);
  scene.add_instance(scene.add_rigid_mesh({{a, b, c}, {a, c, d}}), glm::mat4(1.0f));
  scene.commit();
  CompositeOptions opt;
  opt.lights = {VirtualLight{{0.0f, -1.0f, 0.0f}, glm::vec3(1.0f)}};
  opt.threads = 2;
  const MaterialLookup mirror = [](const core::Hit&) { return VirtualMaterial{VirtualMaterial::kMirror, glm::vec3(1.0f), 1.5f}; };
  const ColorImage out = composite(frame, scene, mirror, opt);
  int checked = 0;
  for (int y = 20; y < kH - 20; y += 3) {
    for (int x = 0; x < kW; x += 2) {
      const glm::dvec3 dir((x + 0.5 - (kCx + 0.5)) / kF, (y + 0.5 - (kCy + 0.5)) / kF, 1.0);
      if (dir.x <= 0.0) continue;
      const double t = 0.25 / dir.x;
      const glm::dvec3 m = t * dir;
      if (m.z < 0.85 || m.z > 1.85 || std::fabs(m.y) > 0.25) continue;  // well inside the mirror
      // the reflected ray meets the wall z = 2 at w; the recorded colour there
      const glm::dvec3 r(-dir.x, dir.y, dir.z);
      const glm::dvec3 w = m + (2.0 - m.z) / r.z * r;
      const long u = std::lround(kF * w.x / w.z + kCx), v = std::lround(kF * w.y / w.z + kCy);
      if (u < 4 || v < 4 || u >= kW - 8 || v >= kH - 8) continue;  // where the depth mesh is
      const uint8_t* expected = frame.color.at(static_cast<int>(u), static_cast<int>(v));
      const uint8_t* seen = out.at(x, y);
      for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(seen[ch], expected[ch], 2) << x << "," << y << " channel " << ch;
      ++checked;
    }
  }
  EXPECT_GT(checked, 50);
}

/// A diffuse box (shadows on the wall and among the virtual objects), a glass box and a mirror, in
/// front of the wall with a noisy depth map (holes, so the hole filling and the colour-guided
/// refinement run): every path of the compositor.
struct MixedScene {
  SensorFrame frame = wall_frame();
  core::TwoLevelScene scene{core::TwoLevelScene::Config::kKdTreeBvh};
  MaterialLookup material;
  MixedScene() {
    for (int i = 0; i < kW * kH; i += 7) frame.depth.depth_m[i] = (i % 3) ? 2.0f + 0.003f * (i % 5) : 0.0f;
    scene.set_static(box(kBoxLo, kBoxHi));
    const auto glass_tris = box({-0.3f, -0.1f, 1.4f}, {-0.1f, 0.1f, 1.6f});
    const core::MeshHandle glass = scene.add_rigid_mesh(glass_tris);
    const VirtualMaterial glass_material{VirtualMaterial::kGlass, glm::vec3(0.9f), 1.5f};
    scene.set_mesh_transmittance(glass, std::vector<float>(glass_tris.size(), shadow_transmittance(glass_material)));
    scene.add_instance(glass, glm::mat4(1.0f));
    const glm::vec3 a(0.3f, 0.05f, 1.2f), b(0.3f, 0.3f, 1.2f), c(0.5f, 0.3f, 1.6f), d(0.5f, 0.05f, 1.6f);
    scene.add_instance(scene.add_rigid_mesh({{a, b, c}, {a, c, d}}), glm::mat4(1.0f));
    scene.commit();
    material = [glass_material](const core::Hit& h) {
      if (h.inst == core::kStaticObject) return VirtualMaterial{VirtualMaterial::kDiffuse, glm::vec3(0.8f, 0.3f, 0.2f), 1.5f};
      if (h.inst == 0) return glass_material;
      return VirtualMaterial{VirtualMaterial::kMirror, glm::vec3(0.95f), 1.5f};
    };
  }
};

/// The same frame for any thread count, 1, 2, 3 and 4 threads: byte-identical.
TEST(Compositor, SameImageForAnyThreadCount) {
  const MixedScene m;
  CompositeOptions opt = shadow_options();
  opt.threads = 1;
  CompositeStats st;
  const ColorImage one = composite(m.frame, m.scene, m.material, opt, &st);
  ASSERT_GT(st.shadowed_real_pixels, 100) << "the test needs shadows on the wall";
  for (const int threads : {2, 3, 4}) {
    opt.threads = threads;
    const ColorImage many = composite(m.frame, m.scene, m.material, opt);
    size_t differ = 0;
    for (size_t i = 0; i < one.rgb.size(); ++i) differ += one.rgb[i] != many.rgb[i];
    EXPECT_EQ(differ, 0u) << threads << " threads";
  }
}

/// Secondary rays traced in packets generation after generation give the image of tracing every
/// generation after the first one ray at a time (the glass box's refractions leave it in the
/// second, and so do the shadow rays at their hits). The sums run in another order, so a channel
/// may differ by one step, and seldom.
TEST(Compositor, PacketGenerationsGiveTheImageOfOneRayAtATime) {
  const MixedScene m;
  CompositeOptions opt = shadow_options();
  opt.packet_generations = false;
  const ColorImage reference = composite(m.frame, m.scene, m.material, opt);
  opt.packet_generations = true;
  const ColorImage packets = composite(m.frame, m.scene, m.material, opt);
  size_t differ = 0, changed = 0;
  int worst = 0;
  for (size_t i = 0; i < reference.rgb.size(); ++i) {
    const int diff = std::abs(static_cast<int>(reference.rgb[i]) - static_cast<int>(packets.rgb[i]));
    worst = std::max(worst, diff);
    differ += diff != 0;
    changed += reference.rgb[i] != m.frame.color.rgb[i];
  }
  ASSERT_GT(changed, 3000u) << "the objects should cover part of the frame";
  EXPECT_LE(worst, 1);
  EXPECT_LT(differ, changed / 100) << "of " << changed << " channels the objects changed";
}

}  // namespace
}  // namespace artrace::ar
