#include "artrace/core/kinematic_tree.h"

#include <stdexcept>
#include <string>

namespace artrace::core {

int KinematicTree::add_node(int parent, const glm::mat4& offset) {
  if (parent >= static_cast<int>(nodes_.size()) || parent < -1) {
    throw std::out_of_range("kinematic tree: parent " + std::to_string(parent) + " does not exist yet");
  }
  nodes_.push_back(Node{parent, offset, glm::mat4(1.0f), glm::mat4(1.0f), {}});
  return static_cast<int>(nodes_.size()) - 1;
}

void KinematicTree::attach(int node, InstanceHandle instance) { nodes_.at(node).instances.push_back(instance); }

void KinematicTree::set_local(int node, const glm::mat4& local) { nodes_.at(node).local = local; }

void KinematicTree::update(TwoLevelScene& scene) {
  for (Node& n : nodes_) {
    const glm::mat4 parent = n.parent < 0 ? glm::mat4(1.0f) : nodes_[n.parent].world;
    n.world = parent * n.offset * n.local;
    for (const InstanceHandle h : n.instances) scene.set_transform(h, n.world);
  }
}

}  // namespace artrace::core
