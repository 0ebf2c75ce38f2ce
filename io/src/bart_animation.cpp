#include "artrace/io/bart_animation.h"

namespace artrace::io {
namespace {

/// The light each triangle of `b` lets through; empty when every one is opaque.
std::vector<float> transmittance(const TriangleBatch& b, const AffScene& scene) {
  std::vector<float> pass(b.size(), 0.0f);
  bool any = false;
  for (size_t i = 0; i < b.size(); ++i) {
    pass[i] = scene.transmittance(b.material[i]);
    any |= pass[i] > 0.0f;
  }
  if (!any) pass.clear();
  return pass;
}

}  // namespace

BartAnimation::BartAnimation(const AffScene& scene, core::TwoLevelScene::Config config) : aff_(scene), scene_(config) {
  // The triangles' transmittance lets shadow rays see through glass in one traversal
  // (TwoLevelScene::transmittance). Deforming triangles carry none, so when one of them is
  // transmissive none is given and the renderer walks blocked shadow rays surface by surface.
  const bool give = !scene.deforming_transmissive();
  scene_.set_static(scene.nodes.empty() ? std::vector<core::Triangle>{} : scene.nodes[0].geometry.tris);
  if (give && !scene.nodes.empty()) {
    std::vector<float> pass = transmittance(scene.nodes[0].geometry, scene);
    if (!pass.empty()) scene_.set_static_transmittance(std::move(pass));
  }
  node_of_.assign(scene.nodes.size(), -1);
  animation_of_.assign(scene.nodes.size(), nullptr);
  for (size_t n = 1; n < scene.nodes.size(); ++n) {
    const AffNode& node = scene.nodes[n];
    const int parent = node.parent > 0 ? node_of_[node.parent] : -1;
    node_of_[n] = kinematics_.add_node(parent, glm::mat4(node.offset));
    const auto it = scene.animations.find(node.animation);
    if (it != scene.animations.end()) animation_of_[n] = &it->second;
    if (!node.geometry.tris.empty()) {
      const core::MeshHandle mesh = scene_.add_rigid_mesh(node.geometry.tris);
      if (give) {
        std::vector<float> pass = transmittance(node.geometry, scene);
        if (!pass.empty()) scene_.set_mesh_transmittance(mesh, std::move(pass));
      }
      const core::InstanceHandle inst = scene_.add_instance(mesh, glm::mat4(1.0f));
      kinematics_.attach(node_of_[n], inst);
      if (instance_node_.size() <= inst.index) instance_node_.resize(inst.index + 1);
      instance_node_[inst.index] = static_cast<uint32_t>(n);
    }
  }
  if (!scene.animated_triangles.empty()) {
    core::TriangleMesh mesh;
    const auto tris = scene.triangles_at(scene.anim_start);
    const size_t first = tris.size() - scene.animated_triangles.size();
    for (size_t i = first; i < tris.size(); ++i) {
      const uint32_t v = static_cast<uint32_t>(mesh.positions.size());
      mesh.positions.insert(mesh.positions.end(), {tris[i].v0, tris[i].v1, tris[i].v2});
      mesh.indices.push_back({v, v + 1, v + 2});
    }
    deforming_ = scene_.add_deformable(std::move(mesh));
    has_deforming_ = true;
  }
  set_time(scene.anim_start);
}

double BartAnimation::set_time(double t) {
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t n = 1; n < aff_.nodes.size(); ++n) {
    kinematics_.set_local(node_of_[n], animation_of_[n] ? glm::mat4(animation_of_[n]->transform(t)) : glm::mat4(1.0f));
  }
  kinematics_.update(scene_);
  if (has_deforming_) {
    core::DeformableMesh& d = scene_.deformable(deforming_);
    const auto tris = aff_.triangles_at(t);
    const size_t first = tris.size() - aff_.animated_triangles.size();
    for (size_t i = first; i < tris.size(); ++i) {
      const size_t v = 3 * (i - first);
      d.positions()[v] = tris[i].v0;
      d.positions()[v + 1] = tris[i].v1;
      d.positions()[v + 2] = tris[i].v2;
    }
    d.restructure();
  }
  scene_.commit();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

uint32_t BartAnimation::material(const core::Hit& hit) const {
  if (!hit.valid()) return 0;
  if (hit.inst == core::kStaticObject) return aff_.nodes[0].geometry.material.at(hit.prim);
  if (hit.inst & 0x80000000u) return aff_.animated_triangles.at(hit.prim).material;
  return aff_.nodes[instance_node_.at(hit.inst)].geometry.material.at(hit.prim);
}

const TriangleBatch* BartAnimation::batch(const core::Hit& hit) const {
  if (!hit.valid() || (hit.inst != core::kStaticObject && (hit.inst & 0x80000000u))) return nullptr;
  if (hit.inst == core::kStaticObject) return &aff_.nodes[0].geometry;
  return &aff_.nodes[instance_node_.at(hit.inst)].geometry;
}

}  // namespace artrace::io
