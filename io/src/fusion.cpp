#include "artrace/io/fusion.h"
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
    if (f.depth.width != f.color.width || f.depth.height != f.color.height) {
      throw std::runtime_error(recording.describe() + ": frame " + std::to_string(k) + ": depth and colour differ in size (fusion needs registered depth)");
    }
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
  open3d::geometry::TriangleMesh mesh;
  for (const glm::vec3& v : m.positions) mesh.vertices_.emplace_back(v.x, v.y, v.z);
  for (const glm::vec3& c : m.colours) {
    mesh.vertex_colors_.emplace_back(core::linear_to_srgb8(c.r) / 255.0, core::linear_to_srgb8(c.g) / 255.0, core::linear_to_srgb8(c.b) / 255.0);
  }
  for (const glm::uvec3& t : m.triangles) mesh.triangles_.emplace_back(t.x, t.y, t.z);
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  // Open3D picks the format by the extension: the temporary name keeps ".ply" at its end
  const std::filesystem::path tmp = path.parent_path() / (path.stem().string() + ".partial.ply");
  if (!open3d::io::WriteTriangleMesh(tmp.string(), mesh, /*write_ascii=*/false, /*compressed=*/false)) {
    std::filesystem::remove(tmp);
    throw std::runtime_error(path.string() + ": cannot write the mesh");
  }
  std::filesystem::rename(tmp, path);
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
