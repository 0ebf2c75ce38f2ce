#include "artrace/io/fusion.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/parse_error.h"

#include "artrace/core/srgb.h"

#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>

#include <chrono>
#include <cstring>

namespace artrace::io {

ar::RoomMesh fuse_recording(ar::FrameSource& recording, const FusionOptions& o, FusionStats* stats,
                            const std::function<void(int, int)>& progress) {
  using namespace open3d;
  const auto t0 = std::chrono::steady_clock::now();
  pipelines::integration::ScalableTSDFVolume volume(o.voxel_m, o.truncation_m, pipelines::integration::TSDFVolumeColorType::RGB8);
  FusionStats st;
  const int total = static_cast<int>(recording.frame_count().value_or(0));
  ar::SensorFrame f;
  geometry::Image colour, depth;
  for (int k = 0; recording.next(f); ++k) {
    if (progress) progress(k + 1, total);
    if (o.every > 1 && k % o.every != 0) continue;
    if (!f.world_from_camera) {
      ++st.without_pose;
      continue;
    }
    ar::require_depth_at_colour_size(f, recording.describe(), "fusion needs depth registered to the colour");
    colour.Prepare(f.color.width, f.color.height, 3, 1);
    std::memcpy(colour.data_.data(), f.color.rgb.data(), f.color.rgb.size());
    depth.Prepare(f.depth.width, f.depth.height, 1, 4);
    std::memcpy(depth.data_.data(), f.depth.depth_m.data(), f.depth.depth_m.size() * 4);
    // depth in metres already: a scale of 1; colour kept as colour
    const auto rgbd = geometry::RGBDImage::CreateFromColorAndDepth(colour, depth, 1.0, o.max_depth_m, false);
    const ar::PinholeIntrinsics& k_ = f.color_intrinsics;
    const camera::PinholeCameraIntrinsic intr(k_.width, k_.height, k_.fx, k_.fy, k_.cx, k_.cy);
    const Eigen::Matrix4d extrinsic = f.world_from_camera->inverse().matrix();  // camera from world
    volume.Integrate(*rgbd, intr, extrinsic);
    ++st.frames;
  }
  if (st.frames == 0) throw std::runtime_error(recording.describe() + ": no frame has a pose to fuse it with");
  const std::shared_ptr<geometry::TriangleMesh> mesh = volume.ExtractTriangleMesh();
  ar::RoomMesh out;
  out.positions.reserve(mesh->vertices_.size());
  for (const Eigen::Vector3d& v : mesh->vertices_) out.positions.emplace_back(v.x(), v.y(), v.z());
  for (const Eigen::Vector3d& c : mesh->vertex_colors_) {
    // Open3D keeps the 8-bit sRGB values as fractions: back to linear light
    auto lin = [](double x) { return core::srgb8_to_linear(static_cast<uint8_t>(std::lround(std::clamp(x, 0.0, 1.0) * 255.0))); };
    out.colours.emplace_back(lin(c.x()), lin(c.y()), lin(c.z()));
  }
  out.colours.resize(out.positions.size(), glm::vec3(0.5f));
  for (const Eigen::Vector3i& t : mesh->triangles_) out.triangles.emplace_back(t.x(), t.y(), t.z());
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (stats) *stats = st;
  return out;
}

void write_room_ply(const ar::RoomMesh& m, const std::filesystem::path& path) {
  // Written here rather than by Open3D: its PLY writer reports success when the disk fills (its
  // RPly's failed close is not passed on), leaving a cut mesh. Binary PLY, little-endian: each
  // vertex x, y, z (float) and its sRGB colour (uchar), each face three vertex indices (int).
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment artrace fuse\nelement vertex " + std::to_string(m.positions.size()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
                    "property uchar blue\nelement face " + std::to_string(m.triangles.size()) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + m.positions.size() * 15 + m.triangles.size() * 13);
  auto put32 = [&out](uint32_t u) {
    for (int b = 0; b < 4; ++b) out.push_back(static_cast<char>((u >> (8 * b)) & 0xffu));
  };
  auto put_float = [&put32](float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof(u));
    put32(u);
  };
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const glm::vec3& v = m.positions[i];
    const glm::vec3 c = i < m.colours.size() ? m.colours[i] : glm::vec3(0.5f);
    put_float(v.x);
    put_float(v.y);
    put_float(v.z);
    for (const float x : {c.r, c.g, c.b}) out.push_back(static_cast<char>(core::linear_to_srgb8(x)));
  }
  for (const glm::uvec3& t : m.triangles) {
    out.push_back(3);
    put32(t.x);
    put32(t.y);
    put32(t.z);
  }
  write_file_atomically(path, out);
}

ar::RoomMesh read_room_ply(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw ParseError(path.string(), 0, 0, "no such file");
  open3d::geometry::TriangleMesh mesh;
  if (!open3d::io::ReadTriangleMesh(path.string(), mesh) || mesh.triangles_.empty()) {
    throw ParseError(path.string(), 0, 0, "not a triangle mesh Open3D reads (PLY, OBJ, STL, OFF, glTF), or one without triangles");
  }
  ar::RoomMesh out;
  for (const Eigen::Vector3d& v : mesh.vertices_) {
    if (!v.allFinite() || v.cwiseAbs().maxCoeff() > 1e6) throw ParseError(path.string(), 0, 0, "a vertex lies beyond +-1e6 m or is not finite");
    out.positions.emplace_back(v.x(), v.y(), v.z());
  }
  for (const Eigen::Vector3d& c : mesh.vertex_colors_) {
    auto lin = [](double x) { return core::srgb8_to_linear(static_cast<uint8_t>(std::lround(std::clamp(x, 0.0, 1.0) * 255.0))); };
    out.colours.emplace_back(lin(c.x()), lin(c.y()), lin(c.z()));
  }
  if (out.colours.size() != out.positions.size()) out.colours.assign(out.positions.size(), glm::vec3(0.5f));
  for (const Eigen::Vector3i& t : mesh.triangles_) {
    if ((t.array() < 0).any() || (t.array() >= static_cast<int>(out.positions.size())).any()) {
      throw ParseError(path.string(), 0, 0, "a triangle indexes past the " + std::to_string(out.positions.size()) + " vertices");
    }
    out.triangles.emplace_back(t.x(), t.y(), t.z());
  }
  return out;
}

}  // namespace artrace::io
