// Hierarchically transformed objects: rigid parts hung in a tree of transforms. The application
// sets each node's local (animated) transform; update() composes world transforms parent first
// and hands them to the parts' instances in a two-level scene.
#pragma once

#include "artrace/core/two_level_scene.h"

#include <glm/mat4x4.hpp>

#include <vector>

namespace artrace::core {

class KinematicTree {
 public:
  /// Adds a node below `parent` (-1 for a root): world = world(parent) · offset · local.
  /// Parents must be added before their children. Returns the node index.
  int add_node(int parent, const glm::mat4& offset = glm::mat4(1.0f));
  /// Hangs an instance on a node; its transform follows the node's world transform.
  void attach(int node, InstanceHandle instance);
  /// The animated part of a node's transform (throws std::out_of_range for a bad node).
  void set_local(int node, const glm::mat4& local);
  /// Composes world transforms and updates every attached instance in `scene` (commit() after).
  void update(TwoLevelScene& scene);
  const glm::mat4& world(int node) const { return nodes_.at(node).world; }
  size_t size() const { return nodes_.size(); }

 private:
  struct Node {
    int parent;
    glm::mat4 offset, local, world;
    std::vector<InstanceHandle> instances;
  };
  std::vector<Node> nodes_;
};

}  // namespace artrace::core
