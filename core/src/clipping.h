// Bounds of the parts of a triangle on either side of a plane, for the builders that split
// triangles' references (the kd-tree's perfect splits, the wide BVH's spatial splits).
#pragma once

#include "artrace/core/geometry.h"

#include <glm/gtc/type_ptr.hpp>

#include <cmath>

namespace artrace::core::detail {

/// v[i] through glm's pointer to the three coordinates instead of its operator[], a switch on i
/// (a branch an access, in loops over all triangles): 6% of the build's instructions.
inline float coord(const glm::vec3& v, int i) { return glm::value_ptr(v)[i]; }

inline void set_coord(glm::vec3& v, int i, float x) { glm::value_ptr(v)[i] = x; }

/// Sutherland-Hodgman: keeps the part of polygon `in` (n vertices) on one side of a plane.
inline int clip_polygon(const glm::vec3* in, int n, glm::vec3* out, int axis, float plane, bool keep_below) {
  if (n <= 0) return 0;
  int m = 0;
  const glm::vec3* cur = &in[n - 1];  // edges (cur, nxt), starting with the closing one
  bool cur_in = keep_below ? coord(*cur, axis) <= plane : coord(*cur, axis) >= plane;
  for (int i = 0; i < n; ++i) {
    const glm::vec3* nxt = &in[i];
    const bool nxt_in = keep_below ? coord(*nxt, axis) <= plane : coord(*nxt, axis) >= plane;
    if (cur_in != nxt_in) {
      const float s = (plane - coord(*cur, axis)) / (coord(*nxt, axis) - coord(*cur, axis));
      glm::vec3 p = *cur + s * (*nxt - *cur);
      set_coord(p, axis, plane);
      out[m++] = p;
    }
    if (nxt_in) out[m++] = *nxt;
    cur = nxt;
    cur_in = nxt_in;
  }
  return m;
}

inline Aabb intersect_boxes(const Aabb& a, const Aabb& b) {
  Aabb r;
  r.lo = glm::max(a.lo, b.lo);
  r.hi = glm::min(a.hi, b.hi);
  return r;
}

/// Bounds of the parts of `tri` inside the two children of a split at `pos` on `axis` (their
/// voxels `voxel_left`, `voxel_right`): "perfect split" clipping. The triangle is clipped to the
/// parent voxel (only the planes it crosses), then the polygon is cut by the split plane in one
/// pass (a vertex in the plane goes to both sides): one clip of the triangle for both children
/// instead of one each. A side where rounding clips everything away gets the conservative box
/// intersection.
inline void clipped_bounds_split(const Triangle& tri, const Aabb& voxel_left, const Aabb& voxel_right, int axis, float pos,
                                 Aabb& left, Aabb& right) {
  Aabb voxel = voxel_left;
  voxel.hi = voxel_right.hi;
  const Aabb tri_box = Aabb::of(tri);
  glm::vec3 buf_a[16] = {tri.v0, tri.v1, tri.v2};
  glm::vec3 buf_b[16];
  glm::vec3* in = buf_a;
  glm::vec3* out = buf_b;
  int n = 3;
  for (int a = 0; a < 3 && n > 0; ++a) {
    if (coord(tri_box.lo, a) < coord(voxel.lo, a)) {
      n = clip_polygon(in, n, out, a, coord(voxel.lo, a), false);
      std::swap(in, out);
    }
    if (n > 0 && coord(tri_box.hi, a) > coord(voxel.hi, a)) {
      n = clip_polygon(in, n, out, a, coord(voxel.hi, a), true);
      std::swap(in, out);
    }
  }
  // clip_polygon()'s rule for both sides of the split plane at once, into bounds instead of
  // polygons (two clip_polygon() calls instead: 3.3% more build instructions on the kitchen)
  Aabb bl, br;
  if (n > 0) {
    const glm::vec3* cur = &in[n - 1];
    float cur_x = coord(*cur, axis);
    for (int i = 0; i < n; ++i) {
      const glm::vec3* nxt = &in[i];
      const float nxt_x = coord(*nxt, axis);
      if ((cur_x < pos && nxt_x > pos) || (cur_x > pos && nxt_x < pos)) {
        const float t = (pos - cur_x) / (nxt_x - cur_x);
        glm::vec3 p = *cur + t * (*nxt - *cur);
        set_coord(p, axis, pos);
        bl.extend(p);
        br.extend(p);
      }
      if (nxt_x <= pos) bl.extend(*nxt);
      if (nxt_x >= pos) br.extend(*nxt);
      cur = nxt;
      cur_x = nxt_x;
    }
  }
  // The points made by clipping are rounded, so a box of them can fall short of the part it
  // bounds: a sliver leaning a fraction of an ulp off a plane comes out lying in it, and is then
  // handed to one side only, possibly the wrong one, whose own clipping of the triangle keeps
  // little or nothing of it. Widened by a margin far above the rounding (2^-20 of the
  // triangle's magnitude), then cut back to the triangle's own box (its vertices are exact, so a
  // triangle that does lie in a plane stays in it) and to the voxel.
  if (n > 0) {
    const glm::vec3 margin = glm::max(glm::abs(tri_box.lo), glm::abs(tri_box.hi)) * 0x1p-20f;
    for (Aabb* b : {&bl, &br}) {
      if (b->empty()) continue;
      b->lo -= margin;
      b->hi += margin;
      *b = intersect_boxes(*b, tri_box);
    }
  }
  left = intersect_boxes(bl, voxel_left);
  if (left.empty()) left = intersect_boxes(tri_box, voxel_left);
  right = intersect_boxes(br, voxel_right);
  if (right.empty()) right = intersect_boxes(tri_box, voxel_right);
}

}  // namespace artrace::core::detail
