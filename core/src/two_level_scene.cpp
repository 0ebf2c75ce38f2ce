#include "artrace/core/two_level_scene.h"
#include "kernels.h"
#include "quarters.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace artrace::core {
namespace {

void set_rows(float out[12], const glm::mat4& m) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) out[4 * r + c] = m[c][r];
  }
}

/// The top level: a binary tree over the objects' world boxes, one object a leaf, each split the
/// SAH's best over every cut of the objects sorted by their centres on each axis (ties by index:
/// the same tree every time), median splits below depth 32. An object costs a transform and a
/// BVH traversal, far more than a box test, so no leaf holds two. The objects are sorted once on
/// each axis; a split partitions the three orders stably, so each level costs O(n).
class TopBuilder {
 public:
  TopBuilder(const std::vector<InstanceData>& data, std::vector<TopNode>& top)
      : data_(data), top_(top), left_(data.size()), scratch_(data.size()), right_area_(data.size()) {
    const uint32_t n = static_cast<uint32_t>(data.size());
    std::vector<glm::vec3> centres;  // twice the centre of each world box
    centres.reserve(n);
    for (const InstanceData& d : data) centres.push_back(d.world_bounds.lo + d.world_bounds.hi);
    for (int a = 0; a < 3; ++a) {
      sorted_[a].resize(n);
      for (uint32_t i = 0; i < n; ++i) sorted_[a][i] = i;
      std::sort(sorted_[a].begin(), sorted_[a].end(), [&](uint32_t x, uint32_t y) {
        return centres[x][a] < centres[y][a] || (centres[x][a] == centres[y][a] && x < y);
      });
    }
  }

  /// Builds the tree into `top` (cleared); returns the objects in leaf order (a leaf's `first`
  /// indexes it).
  std::vector<uint32_t> run() {
    top_.assign(1, TopNode{});
    build(0, 0, static_cast<uint32_t>(data_.size()), 0);
    return std::move(sorted_[0]);  // every order now holds each leaf's objects in its range
  }

 private:
  void build(uint32_t node, uint32_t begin, uint32_t end, int depth) {
    Aabb box;
    for (uint32_t i = begin; i < end; ++i) box.extend(data_[sorted_[0][i]].world_bounds);
    top_[node].bounds = box;
    const uint32_t n = end - begin;
    if (n <= 1 || depth >= 48) {
      top_[node].first = begin;
      top_[node].count = static_cast<uint16_t>(n);
      return;
    }
    int axis = 0;
    uint32_t split = n / 2;
    if (depth < kSahDepth) {
      // equal costs (objects in one place) go to the more even split
      auto uneven = [n](uint32_t k) { return k > n - k ? 2 * k - n : n - 2 * k; };
      float best_cost = kInfinity;
      for (int a = 0; a < 3; ++a) {
        const uint32_t* objects = sorted_[a].data() + begin;
        Aabb right;
        for (uint32_t k = n - 1; k > 0; --k) {
          right.extend(data_[objects[k]].world_bounds);
          right_area_[k] = right.surface_area();
        }
        Aabb left;
        for (uint32_t k = 1; k < n; ++k) {
          left.extend(data_[objects[k - 1]].world_bounds);
          const float cost = left.surface_area() * static_cast<float>(k) + right_area_[k] * static_cast<float>(n - k);
          if (cost < best_cost || (cost == best_cost && uneven(k) < uneven(split))) {
            best_cost = cost;
            axis = a;
            split = k;
          }
        }
      }
    } else {
      // a chain of lopsided SAH splits: medians of the widest axis from here, so that the depth
      // (and a leaf at the depth cap) stays bounded whatever the boxes. Defensive: with float
      // areas a chain this deep needs boxes growing ~30x per object, past float's range, and ties
      // go to the even cut; no test reaches it.
      float widest = -1.0f;
      for (int a = 0; a < 3; ++a) {
        auto c = [&](uint32_t i) { return data_[i].world_bounds.lo[a] + data_[i].world_bounds.hi[a]; };
        const float extent = c(sorted_[a][end - 1]) - c(sorted_[a][begin]);
        if (extent > widest) widest = extent, axis = a;
      }
    }
    // the first `split` objects of the chosen order go left; the other orders follow, stably
    for (uint32_t i = begin; i < end; ++i) left_[sorted_[axis][i]] = i < begin + split;
    for (int a = 0; a < 3; ++a) {
      if (a == axis) continue;
      uint32_t* objects = sorted_[a].data();
      uint32_t l = begin, r = 0;
      for (uint32_t i = begin; i < end; ++i) {
        if (left_[objects[i]]) objects[l++] = objects[i];
        else scratch_[r++] = objects[i];
      }
      std::copy(scratch_.begin(), scratch_.begin() + r, objects + l);
    }
    const uint32_t child = static_cast<uint32_t>(top_.size());
    top_.resize(child + 2);
    top_[node].first = child;
    top_[node].count = 0;
    top_[node].axis = static_cast<uint16_t>(axis);
    build(child, begin, begin + split, depth + 1);
    build(child + 1, begin + split, end, depth + 1);
  }

  static constexpr int kSahDepth = 32;  ///< below this depth, median splits

  const std::vector<InstanceData>& data_;
  std::vector<TopNode>& top_;
  std::vector<uint32_t> sorted_[3];  ///< the objects by centre on each axis, a node's as a range
  std::vector<uint8_t> left_;        ///< per object: goes to the left child of the node being split
  std::vector<uint32_t> scratch_;    ///< the right side of a partition
  std::vector<float> right_area_;    ///< the area of a node's objects from k on
};

}  // namespace

// ---- DeformableMesh

DeformableMesh::DeformableMesh(TriangleMesh mesh) : mesh_(std::move(mesh)) {
  flatten();
  bvh_.rebuild(tris_);
  fingerprint_ = index_fingerprint();
}

uint64_t DeformableMesh::index_fingerprint() const {
  uint64_t h = 1469598103934665603ull ^ mesh_.indices.size();
  for (const glm::uvec3& t : mesh_.indices) {
    for (int k = 0; k < 3; ++k) {
      h ^= t[k];
      h *= 1099511628211ull;
    }
  }
  return h;
}

void DeformableMesh::flatten() {
  tris_.clear();
  mesh_.flatten_into(tris_);
}

void DeformableMesh::refit() {
  if (index_fingerprint() != fingerprint_) {
    throw std::logic_error("deformable mesh: the index buffer changed since the last rebuild(); "
                           "refit() keeps the topology, call rebuild()");
  }
  flatten();
  bvh_.refit(tris_);
}

uint32_t DeformableMesh::restructure() {
  if (index_fingerprint() != fingerprint_) {
    throw std::logic_error("deformable mesh: the index buffer changed since the last rebuild(); "
                           "restructure() keeps the topology, call rebuild()");
  }
  flatten();
  return bvh_.restructure(tris_);
}

void DeformableMesh::rebuild() {
  flatten();
  bvh_.rebuild(tris_);
  fingerprint_ = index_fingerprint();
}

// ---- TwoLevelScene

TwoLevelScene::Config TwoLevelScene::parse_config(const std::string& name) {
  if (name == "bvh") return Config::kBvh;
  if (name == "kdtree+bvh") return Config::kKdTreeBvh;
  throw std::invalid_argument("unknown scene configuration '" + name + "' (expected bvh or kdtree+bvh)");
}

void TwoLevelScene::set_static(std::vector<Triangle> tris, bool single_ray_bvh) {
  if (config_ == Config::kKdTreeBvh) {
    wide_ = single_ray_bvh ? WideBvh(tris) : WideBvh();
    kd_ = KdTree(std::move(tris));
  } else {
    static_bvh_ = std::make_unique<Bvh>(std::move(tris));
  }
  static_pass_.clear();
  dirty_ = true;
}

namespace {

std::vector<float> checked_pass(std::vector<float> pass, size_t triangles, const char* what) {
  if (pass.size() != triangles) {
    throw std::invalid_argument(std::string(what) + ": " + std::to_string(pass.size()) + " values for " +
                                std::to_string(triangles) + " triangles");
  }
  for (size_t i = 0; i < pass.size(); ++i) {
    if (!(pass[i] >= 0.0f && pass[i] <= 1.0f)) {
      throw std::invalid_argument(std::string(what) + ": triangle " + std::to_string(i) + " lets " +
                                  std::to_string(pass[i]) + " of the light through (expected 0 to 1)");
    }
  }
  return pass;
}

}  // namespace

void TwoLevelScene::set_static_transmittance(std::vector<float> pass) {
  const size_t n = config_ == Config::kKdTreeBvh ? kd_.triangles().size()
                                                 : (static_bvh_ ? static_bvh_->triangles().size() : 0);
  static_pass_ = checked_pass(std::move(pass), n, "set_static_transmittance");
  has_transmittance_ = true;
  dirty_ = true;
}

void TwoLevelScene::set_mesh_transmittance(MeshHandle mesh, std::vector<float> pass) {
  if (mesh.index >= meshes_.size() || meshes_[mesh.index].generation != mesh.generation) {
    throw std::invalid_argument("set_mesh_transmittance: invalid mesh handle " + std::to_string(mesh.index));
  }
  RigidMesh& m = meshes_[mesh.index];
  m.pass = checked_pass(std::move(pass), m.bvh->triangles().size(), "set_mesh_transmittance");
  has_transmittance_ = true;
  dirty_ = true;
}

void TwoLevelScene::set_deformable_transmittance(DeformableHandle mesh, std::vector<float> pass) {
  const DeformableMesh& d = deformable(mesh);
  deformables_[mesh.index].pass = checked_pass(std::move(pass), d.mesh().indices.size(), "set_deformable_transmittance");
  has_transmittance_ = true;
}

MeshHandle TwoLevelScene::add_rigid_mesh(std::vector<Triangle> object_space) {
  RigidMesh m;
  m.bvh = std::make_unique<Bvh>(std::move(object_space));
  meshes_.push_back(std::move(m));
  dirty_ = true;
  return {static_cast<uint32_t>(meshes_.size() - 1), 0};
}

InstanceHandle TwoLevelScene::add_instance(MeshHandle mesh, const glm::mat4& world_from_object) {
  if (mesh.index >= meshes_.size() || meshes_[mesh.index].generation != mesh.generation) {
    throw std::invalid_argument("add_instance: invalid mesh handle " + std::to_string(mesh.index));
  }
  Instance inst;
  inst.mesh = mesh.index;
  inst.alive = true;
  inst.world_from_object = world_from_object;
  inst.normal_to_world = glm::transpose(glm::inverse(glm::mat3(world_from_object)));
  // reuse a removed slot (its generation moves on, so old handles to it stay invalid)
  for (uint32_t i = 0; i < instances_.size(); ++i) {
    if (!instances_[i].alive) {
      inst.generation = instances_[i].generation;
      instances_[i] = inst;
      dirty_ = true;
      return {i, inst.generation};
    }
  }
  instances_.push_back(inst);
  dirty_ = true;
  return {static_cast<uint32_t>(instances_.size() - 1), 0};
}

TwoLevelScene::Instance& TwoLevelScene::checked(InstanceHandle h) {
  if (h.index >= instances_.size() || !instances_[h.index].alive || instances_[h.index].generation != h.generation) {
    throw std::invalid_argument("stale or invalid instance handle " + std::to_string(h.index) + " (generation " +
                                std::to_string(h.generation) + ")");
  }
  return instances_[h.index];
}

void TwoLevelScene::set_transform(InstanceHandle h, const glm::mat4& world_from_object) {
  Instance& inst = checked(h);
  inst.world_from_object = world_from_object;
  inst.normal_to_world = glm::transpose(glm::inverse(glm::mat3(world_from_object)));
  dirty_ = true;
}

void TwoLevelScene::remove_instance(InstanceHandle h) {
  Instance& inst = checked(h);
  inst.alive = false;
  ++inst.generation;
  dirty_ = true;
}

DeformableHandle TwoLevelScene::add_deformable(TriangleMesh world_space) {
  Deformable d;
  d.mesh = std::make_unique<DeformableMesh>(std::move(world_space));
  deformables_.push_back(std::move(d));
  dirty_ = true;
  return {static_cast<uint32_t>(deformables_.size() - 1), 0};
}

DeformableMesh& TwoLevelScene::deformable(DeformableHandle h) {
  if (h.index >= deformables_.size() || !deformables_[h.index].mesh || deformables_[h.index].generation != h.generation) {
    throw std::invalid_argument("stale or invalid deformable handle " + std::to_string(h.index));
  }
  dirty_ = true;  // the application is about to edit it
  return *deformables_[h.index].mesh;
}

void TwoLevelScene::remove_deformable(DeformableHandle h) {
  deformable(h);
  deformables_[h.index].mesh.reset();
  ++deformables_[h.index].generation;
}

void TwoLevelScene::commit() {
  data_.clear();
  const glm::mat4 identity(1.0f);
  auto add = [&](const Bvh& bvh, const glm::mat4& world_from_object, uint32_t id, const std::vector<float>& pass) {
    if (bvh.triangles().empty()) return;
    InstanceData d;
    d.bvh = bvh.view();
    d.bvh.pass = pass.empty() ? nullptr : pass.data();
    set_rows(d.object_from_world, glm::inverse(world_from_object));
    d.world_bounds = transform_box(bvh.bounds(), world_from_object);
    // An object whose world box is not finite (a NaN or infinite transform, or infinite
    // vertices) is left out: a ray could not hit it anyway, and a NaN box would pass every
    // slab test (vmin and vmax return the operand that is not NaN), sending every ray into it.
    for (int a = 0; a < 3; ++a) {
      if (!std::isfinite(d.world_bounds.lo[a]) || !std::isfinite(d.world_bounds.hi[a])) return;
    }
    d.id = id;
    data_.push_back(d);
  };
  if (static_bvh_) add(*static_bvh_, identity, kStaticObject, static_pass_);
  for (uint32_t i = 0; i < instances_.size(); ++i) {
    const Instance& inst = instances_[i];
    if (inst.alive) add(*meshes_[inst.mesh].bvh, inst.world_from_object, i, meshes_[inst.mesh].pass);
  }
  for (uint32_t i = 0; i < deformables_.size(); ++i) {
    const Deformable& d = deformables_[i];
    if (!d.mesh) continue;
    if (!d.pass.empty() && d.pass.size() != d.mesh->bvh().triangles().size()) {
      throw std::logic_error("TwoLevelScene::commit: deformable mesh " + std::to_string(i) + " has " +
                             std::to_string(d.mesh->bvh().triangles().size()) + " triangles but " +
                             std::to_string(d.pass.size()) + " transmittance values (set them again after a rebuild)");
    }
    add(d.mesh->bvh(), identity, deformable_object_id({i, 0}), d.pass);
  }
  top_.clear();
  order_.clear();
  if (!data_.empty()) order_ = TopBuilder(data_, top_).run();
  dirty_ = false;
}

uint32_t TwoLevelScene::top_depth() const {
  uint32_t deepest = 0;
  std::vector<std::pair<uint32_t, uint32_t>> todo;  // node, its level
  if (!top_.empty()) todo.emplace_back(0, 1);
  while (!todo.empty()) {
    const auto [node, level] = todo.back();
    todo.pop_back();
    deepest = std::max(deepest, level);
    if (top_[node].count == 0) {
      todo.emplace_back(top_[node].first, level + 1);
      todo.emplace_back(top_[node].first + 1, level + 1);
    }
  }
  return deepest;
}

namespace {

void require_committed(bool dirty) {
  if (dirty) throw std::logic_error("two-level scene: call commit() after editing, before tracing");
}

}  // namespace

Hit TwoLevelScene::intersect(const Ray& ray) const {
  require_committed(dirty_);
  Hit h;
  if (config_ == Config::kKdTreeBvh) {
    h = wide_.empty() ? kd_.intersect(ray) : wide_.intersect(ray);
    if (h.valid()) h.inst = kStaticObject;
  }
  const TwoLevelView view{top_.data(), order_.data(), data_.data(), static_cast<uint32_t>(top_.size())};
  sse::two_level_intersect_single(view, ray, h);
  return h;
}

bool TwoLevelScene::occluded(const Ray& ray) const {
  require_committed(dirty_);
  if (config_ == Config::kKdTreeBvh && (wide_.empty() ? kd_.occluded(ray) : wide_.occluded(ray))) return true;
  const TwoLevelView view{top_.data(), order_.data(), data_.data(), static_cast<uint32_t>(top_.size())};
  return sse::two_level_occluded_single(view, ray);
}

namespace {

// Per-lane bookkeeping of a packet's results, a quarter at a time (quarters.h): a loop over the 16
// lanes with a branch each cost more than the rest of a two-level shadow call's own work. The
// lanes outside `mask` are read and written back unchanged.

/// trans[i] = 1 for the lanes of `mask`.
inline void set_one(LaneMask mask, float* trans) {
  for (int h = 0; h < kQuarters; ++h) {
    store4(trans, h, select4(mask4(mask >> (4 * h)), F4{} + 1.0f, load4<F4>(trans, h)));
  }
}

/// The lanes of `mask` whose trans[i] > 0.
inline LaneMask positive(LaneMask mask, const float* trans) {
  LaneMask out = 0;
  for (int h = 0; h < kQuarters; ++h) out |= bits4(load4<F4>(trans, h) > F4{}) << (4 * h);
  return out & mask;
}

/// trans[i] *= by[i] for the lanes of `mask`.
inline void multiply(LaneMask mask, float* trans, const float* by) {
  for (int h = 0; h < kQuarters; ++h) {
    const F4 t = load4<F4>(trans, h);
    store4(trans, h, select4(mask4(mask >> (4 * h)), t * load4<F4>(by, h), t));
  }
}

/// hits.inst[i] = kStaticObject for the lanes of `mask` with a hit.
inline void mark_static(LaneMask mask, HitPacket& hits) {
  for (int h = 0; h < kQuarters; ++h) {
    const M4 hit = mask4(mask >> (4 * h)) & (load4<M4>(hits.prim, h) != static_cast<int32_t>(kInvalidId));
    store4(hits.inst, h, select4(hit, M4{} + static_cast<int32_t>(kStaticObject), load4<M4>(hits.inst, h)));
  }
}

}  // namespace

void TwoLevelScene::intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits, Coherence coherence) const {
  require_committed(dirty_);
  mask &= kAllLanes;
  if (config_ == Config::kKdTreeBvh) {
    if (coherence == Coherence::kCoherent && !wide_.empty() && WideBvh::frustums_pay(mask)) {
      wide_.intersect(rays, mask, hits);
    } else {
      kd_.intersect(rays, mask, hits);
    }
    mark_static(mask, hits);
  } else {
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((mask >> i) & 1u)) continue;  // the other lanes keep what they hold, as above
      hits.t[i] = rays.tmax[i];
      hits.u[i] = hits.v[i] = 0.0f;
      hits.prim[i] = hits.inst[i] = kInvalidId;
    }
  }
  if (top_.empty() || mask == 0) return;
  const TwoLevelView view{top_.data(), order_.data(), data_.data(), static_cast<uint32_t>(top_.size())};
  packet_kernels().two_level_intersect(view, rays, mask, hits);
}

LaneMask TwoLevelScene::occluded(const RayPacket& rays, LaneMask mask, ShadowHint* hint) const {
  require_committed(dirty_);
  mask &= kAllLanes;
  LaneMask blocked = config_ == Config::kKdTreeBvh ? kd_.occluded(rays, mask, hint) : 0u;
  const LaneMask rest = mask & ~blocked;
  if (top_.empty() || rest == 0) return blocked;
  const TwoLevelView view{top_.data(), order_.data(), data_.data(), static_cast<uint32_t>(top_.size())};
  return blocked | packet_kernels().two_level_occluded(view, rays, rest);
}

LaneMask TwoLevelScene::transmittance(const RayPacket& rays, LaneMask mask, float* trans, ShadowHint* hint) const {
  require_committed(dirty_);
  mask &= kAllLanes;
  LaneMask unsure = 0;
  if (config_ == Config::kKdTreeBvh && !kd_.prim_refs().empty() && mask != 0) {
    // the kernel writes every lane of `mask`
    KdTreeView kd = kd_.view(hint);
    kd.pass = static_pass_.empty() ? nullptr : static_pass_.data();
    unsure = packet_kernels().transmittance(kd, rays, mask, trans);
  } else {
    set_one(mask, trans);
  }
  const LaneMask rest = positive(mask, trans);
  if (top_.empty() || rest == 0) return unsure;
  const TwoLevelView view{top_.data(), order_.data(), data_.data(), static_cast<uint32_t>(top_.size())};
  float objects[kPacketSize] = {};  // multiply() reads every lane
  unsure |= packet_kernels().two_level_transmittance(view, rays, rest, objects);
  multiply(rest, trans, objects);
  return unsure;
}

glm::mat4 TwoLevelScene::world_from_object(const Hit& hit) const {
  if (hit.inst == kStaticObject || (hit.inst & 0x80000000u)) return glm::mat4(1.0f);
  return instances_.at(hit.inst).world_from_object;
}

glm::mat3 TwoLevelScene::normal_to_world(const Hit& hit) const {
  if (hit.inst == kStaticObject || (hit.inst & 0x80000000u)) return glm::mat3(1.0f);
  return instances_.at(hit.inst).normal_to_world;
}

Aabb TwoLevelScene::bounds() const {
  Aabb b = top_.empty() ? Aabb{} : top_[0].bounds;
  if (config_ == Config::kKdTreeBvh) b.extend(kd_.bounds());
  return b;
}

size_t TwoLevelScene::instance_count() const {
  return static_cast<size_t>(std::count_if(instances_.begin(), instances_.end(), [](const Instance& i) { return i.alive; }));
}

template <class Fn>
void TwoLevelScene::for_each_bvh(const Fn& fn) const {
  if (static_bvh_) fn(*static_bvh_);
  for (const RigidMesh& m : meshes_) fn(*m.bvh);
  for (const Deformable& d : deformables_) {
    if (d.mesh) fn(d.mesh->bvh());
  }
}

namespace {

void accumulate(BvhStats& total, const BvhStats& s) {
  total.nodes_built += s.nodes_built;
  total.nodes_unbuilt += s.nodes_unbuilt;
  total.leaves += s.leaves;
  total.max_depth = std::max(total.max_depth, s.max_depth);
}

}  // namespace

BvhStats TwoLevelScene::bvh_stats() const {
  BvhStats total;
  for_each_bvh([&](const Bvh& b) { accumulate(total, b.stats()); });
  return total;
}

BvhStats TwoLevelScene::bvh_stats_full() const {
  BvhStats total;
  for_each_bvh([&](const Bvh& b) { accumulate(total, Bvh(b.triangles(), /*eager=*/true).stats()); });
  return total;
}

}  // namespace artrace::core
