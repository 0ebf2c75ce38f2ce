#include "artrace/ar/plane_fit.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace artrace::ar {
namespace {

/// Least squares: the centroid and the direction of least spread.
bool refit(const std::vector<Eigen::Vector3d>& pts, const std::vector<int>& idx, Plane& p) {
  if (idx.size() < 3) return false;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const int i : idx) c += pts[static_cast<size_t>(i)];
  c /= static_cast<double>(idx.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const int i : idx) {
    const Eigen::Vector3d d = pts[static_cast<size_t>(i)] - c;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  if (es.info() != Eigen::Success) return false;
  Eigen::Vector3d n = es.eigenvectors().col(0);  // eigenvalues ascending
  if (p.normal.dot(n) < 0.0) n = -n;             // keep the side the caller chose
  p.normal = n.normalized();
  p.point = c;
  return true;
}

std::vector<int> inliers_of(const std::vector<Eigen::Vector3d>& pts, const Plane& p, double threshold) {
  std::vector<int> in;
  for (size_t i = 0; i < pts.size(); ++i) {
    if (std::fabs(p.distance(pts[i])) <= threshold) in.push_back(static_cast<int>(i));
  }
  return in;
}

Eigen::Vector3d to_world(const SensorFrame& f, double u, double v, double z) {
  const PinholeIntrinsics& k = f.color_intrinsics;
  const Eigen::Vector3d c((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z);
  return f.world_from_camera ? (*f.world_from_camera) * c : c;
}

Eigen::Vector3d camera_position(const SensorFrame& f) {
  return f.world_from_camera ? Eigen::Vector3d(f.world_from_camera->translation()) : Eigen::Vector3d::Zero();
}

}  // namespace

double kinect_sigma_m(double z) { return 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4); }

std::optional<Plane> fit_plane(const std::vector<Eigen::Vector3d>& pts, const RansacOptions& o) {
  if (pts.size() < 3) return std::nullopt;
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  // MSAC (P. H. S. Torr and A. Zisserman, CVIU 78(1), 2000): each point costs its squared distance,
  // at most the band's square. Counting inliers alone cannot tell a surface from a plane tilted
  // across it and a step next to it when both lie within the band.
  const double t2 = o.threshold_m * o.threshold_m;
  Plane best;
  double best_cost = std::numeric_limits<double>::infinity();
  size_t best_count = 0;
  for (int it = 0; it < o.iterations; ++it) {
    const size_t a = pick(rng), b = pick(rng), c = pick(rng);
    if (a == b || b == c || a == c) continue;
    const Eigen::Vector3d n = (pts[b] - pts[a]).cross(pts[c] - pts[a]);
    const double len = n.norm();
    if (!(len > 1e-12)) continue;
    Plane p;
    p.normal = n / len;
    p.point = pts[a];
    if (o.through && std::fabs(p.distance(*o.through)) > o.threshold_m) continue;
    size_t count = 0;
    double cost = 0.0;
    for (const Eigen::Vector3d& q : pts) {
      const double d = p.distance(q);
      const double d2 = d * d;
      count += d2 <= t2;
      cost += std::min(d2, t2);
    }
    if (cost < best_cost) {
      best_cost = cost;
      best_count = count;
      best = p;
    }
  }
  if (best_count < static_cast<size_t>(std::max(3, o.min_inliers)) || static_cast<double>(best_count) < o.min_fraction * pts.size()) {
    return std::nullopt;
  }
  std::vector<int> in = inliers_of(pts, best, o.threshold_m);
  if (!refit(pts, in, best)) return std::nullopt;
  double band = o.threshold_m;
  for (int k = 0; k < 6; ++k) {
    in = inliers_of(pts, best, band);
    std::vector<double> r;
    for (const int i : in) r.push_back(std::fabs(best.distance(pts[static_cast<size_t>(i)])));
    if (r.size() < 3) break;
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    const double narrower = std::min(band, std::max(1e-4, 2.5 * 1.4826 * r[r.size() / 2]));
    if (narrower > 0.95 * band) break;  // settled
    band = narrower;
    in = inliers_of(pts, best, band);
    if (!refit(pts, in, best)) return std::nullopt;
  }
  in = inliers_of(pts, best, band);
  best.inliers = static_cast<int>(in.size());
  double ss = 0.0;
  for (const int i : in) ss += best.distance(pts[static_cast<size_t>(i)]) * best.distance(pts[static_cast<size_t>(i)]);
  best.rms_m = in.empty() ? 0.0 : std::sqrt(ss / in.size());
  return best;
}

namespace {

/// plane_at_pixel with one window radius.
std::optional<Plane> plane_in_window(const SensorFrame& f, int u, int v, int r) {
  const DepthImage& d = f.depth;
  const int stride = std::max(1, r / 12);
  std::vector<Eigen::Vector3d> pts;
  double zsum = 0.0;
  for (int y = std::max(0, v - r); y <= std::min(d.height - 1, v + r); y += stride) {
    for (int x = std::max(0, u - r); x <= std::min(d.width - 1, u + r); x += stride) {
      const float z = d.at(x, y);
      if (!DepthImage::valid(z)) continue;
      pts.push_back(to_world(f, x, y, z));
      zsum += z;
    }
  }
  if (pts.size() < 20) return std::nullopt;
  RansacOptions o;
  // the surface at the pixel itself: the median depth of its 3x3 neighbourhood
  std::vector<float> centre;
  for (int y = std::max(0, v - 1); y <= std::min(d.height - 1, v + 1); ++y)
    for (int x = std::max(0, u - 1); x <= std::min(d.width - 1, u + 1); ++x)
      if (DepthImage::valid(d.at(x, y))) centre.push_back(d.at(x, y));
  if (centre.empty()) return std::nullopt;
  std::nth_element(centre.begin(), centre.begin() + centre.size() / 2, centre.end());
  o.through = to_world(f, u, v, centre[centre.size() / 2]);
  // 3 sigma of the noise at this distance, and the disparity steps (a Kinect's depth is quantised
  // to 1/8 pixel of disparity: about z^2 / (8 b f), 4 mm at 1 m)
  const double z = zsum / pts.size();
  o.threshold_m = std::max(3.0 * kinect_sigma_m(z), 0.004 * z * z);
  std::optional<Plane> p = fit_plane(pts, o);
  if (!p || p->inliers < static_cast<int>(pts.size()) / 2) return std::nullopt;
  const Eigen::Vector3d eye = camera_position(f);
  if (p->normal.dot(eye - p->point) < 0.0) p->normal = -p->normal;
  // the pixel's ray meets the plane
  const Eigen::Vector3d dir = to_world(f, u, v, 1.0) - eye;
  const double den = p->normal.dot(dir);
  if (std::fabs(den) > 1e-9) p->point = eye + dir * (p->normal.dot(p->point - eye) / den);
  p->pixel_u = u;
  p->pixel_v = v;
  return p;
}

}  // namespace

std::optional<Plane> plane_at_pixel(const SensorFrame& f, int u, int v, int r) {
  const DepthImage& d = f.depth;
  if (u < 0 || v < 0 || u >= d.width || v >= d.height) return std::nullopt;
  if (r > 0) return plane_in_window(f, u, v, r);
  // the window: 25 cm around the point seen (more baseline for the normal far away), sampled to
  // about 25 x 25 depths; where other surfaces crowd it (a shelf, a narrow desk between objects),
  // half and a quarter of that, down to 8 pixels
  const float z0 = d.at(u, v);
  const int r0 = DepthImage::valid(z0) ? std::clamp(static_cast<int>(0.25 * f.color_intrinsics.fx / z0), 8, 64) : 12;
  for (int w = r0;; w /= 2) {
    if (std::optional<Plane> p = plane_in_window(f, u, v, std::max(w, 8))) return p;
    if (w <= 8) return std::nullopt;
  }
}

std::vector<Plane> detect_planes(const SensorFrame& f, const PlaneDetection& o) {
  struct Sample {
    Eigen::Vector3d p;
    int u, v;
    double footprint;  ///< the area its stride x stride pixels cover, facing the camera (m^2)
  };
  std::vector<Sample> all;
  const PinholeIntrinsics& k = f.color_intrinsics;
  for (int y = o.stride / 2; y < f.depth.height; y += o.stride) {
    for (int x = o.stride / 2; x < f.depth.width; x += o.stride) {
      const float z = f.depth.at(x, y);
      if (!DepthImage::valid(z) || z > o.max_depth_m) continue;
      all.push_back({to_world(f, x, y, z), x, y, (z * o.stride / k.fx) * (z * o.stride / k.fy)});
    }
  }
  const Eigen::Vector3d eye = camera_position(f);
  std::vector<Plane> out;
  uint64_t seed = 1;
  while (static_cast<int>(out.size()) < o.max_planes && all.size() > 50) {
    std::vector<Eigen::Vector3d> pts(all.size());
    double zsum = 0.0;
    for (size_t i = 0; i < all.size(); ++i) {
      pts[i] = all[i].p;
      zsum += (all[i].p - eye).norm();
    }
    RansacOptions ro;
    ro.seed = seed++;
    ro.iterations = 500;
    const double z = zsum / all.size();
    ro.threshold_m = std::max(3.0 * kinect_sigma_m(z), 0.004 * z * z);
    // a plane need not hold a third of what is left: take the best, then judge it by its area
    ro.min_fraction = 0.0;
    ro.min_inliers = 30;
    std::optional<Plane> p = fit_plane(pts, ro);
    if (!p) break;
    if (p->normal.dot(eye - p->point) < 0.0) p->normal = -p->normal;
    std::vector<int> in = inliers_of(pts, *p, ro.threshold_m);
    // area on the plane: each sample's footprint divided by the cosine between plane and view
    double area = 0.0, ss = 0.0, su = 0.0, sv = 0.0;
    for (const int i : in) {
      const Sample& s = all[static_cast<size_t>(i)];
      const Eigen::Vector3d view = (eye - s.p).normalized();
      area += s.footprint / std::max(0.1, std::fabs(view.dot(p->normal)));
      ss += p->distance(s.p) * p->distance(s.p);
      su += s.u;
      sv += s.v;
    }
    p->area_m2 = area;
    p->rms_m = std::sqrt(ss / std::max<size_t>(1, in.size()));
    // the pixel to list: an inlier where an anchor stands on this plane, i.e. where the fit around
    // the pixel (plane_at_pixel) agrees with it (normals within 5 degrees, within 2 cm), tried
    // from the inliers' image centroid outwards; near an edge the fit around a pixel can take in
    // the neighbouring surface and tilt. A plane without such a pixel is not listed.
    const double cu = su / in.size(), cv = sv / in.size();
    std::vector<std::pair<double, int>> order;
    order.reserve(in.size());
    for (const int i : in) {
      const Sample& s = all[static_cast<size_t>(i)];
      order.emplace_back((s.u - cu) * (s.u - cu) + (s.v - cv) * (s.v - cv), i);
    }
    std::sort(order.begin(), order.end());
    bool anchorable = false;
    for (size_t k = 0; k < std::min<size_t>(order.size(), 64) && !anchorable; ++k) {
      const Sample& s = all[static_cast<size_t>(order[k].second)];
      const std::optional<Plane> local = plane_at_pixel(f, s.u, s.v);
      if (!local || local->normal.dot(p->normal) < std::cos(5.0 * M_PI / 180.0) || std::fabs(p->distance(local->point)) > 0.02) continue;
      anchorable = true;
      p->pixel_u = s.u;
      p->pixel_v = s.v;
      p->point = s.p - p->normal * p->distance(s.p);
    }
    // remove the inliers and go on
    std::vector<char> used(all.size(), 0);
    for (const int i : in) used[static_cast<size_t>(i)] = 1;
    std::vector<Sample> rest;
    for (size_t i = 0; i < all.size(); ++i) {
      if (!used[i]) rest.push_back(all[i]);
    }
    all.swap(rest);
    if (anchorable && p->area_m2 >= o.min_area_m2) out.push_back(*p);
  }
  std::sort(out.begin(), out.end(), [](const Plane& a, const Plane& b) { return a.area_m2 > b.area_m2; });
  return out;
}

}  // namespace artrace::ar
