// A BART scene played through the two-level scene's update API: the static geometry goes into the
// kd-tree (or a BVH), every animated transform node becomes a kinematic-tree node with its geometry
// as a rigid mesh instance, animated triangles (`tpa`) a deformable mesh.
#pragma once

#include "artrace/core/kinematic_tree.h"
#include "artrace/core/two_level_scene.h"
#include "artrace/io/aff_scene.h"

#include <chrono>

namespace artrace::io {

class BartAnimation {
 public:
  BartAnimation(const AffScene& scene, core::TwoLevelScene::Config config);

  /// Moves everything to time t: animation tracks evaluated, kinematic tree updated, deformable
  /// triangles refit, top level committed. Returns the time it took in milliseconds.
  double set_time(double t);

  const core::TwoLevelScene& scene() const { return scene_; }
  const AffScene& aff() const { return aff_; }
  /// Material of the triangle a hit names (index into aff().materials).
  uint32_t material(const core::Hit& hit) const;
  /// The triangles (with normals, texture coordinates) of the object a hit names; hit.prim indexes
  /// them. Null for animated (`tpa`) triangles.
  const TriangleBatch* batch(const core::Hit& hit) const;
  /// AFF node of every instance (indexed by instance slot).
  const std::vector<uint32_t>& instance_nodes() const { return instance_node_; }

 private:
  const AffScene& aff_;
  core::TwoLevelScene scene_;
  core::KinematicTree kinematics_;
  std::vector<int> node_of_;              ///< AFF node -> kinematic node
  std::vector<const KeyframeAnimation*> animation_of_;  ///< per AFF node, null when fixed
  std::vector<uint32_t> instance_node_;   ///< instance index -> AFF node
  core::DeformableHandle deforming_;
  bool has_deforming_ = false;
};

}  // namespace artrace::io
