#include "artrace/ar/depth_model.h"

#include <cmath>
#include <random>

namespace artrace::ar {

void apply_depth_model(DepthImage& depth, const PinholeIntrinsics& k, const DepthModel& m, uint64_t seed) {
  const int w = depth.width, h = depth.height;
  const std::vector<float> exact = depth.depth_m;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  auto at = [&](int x, int y) { return exact[static_cast<size_t>(y) * w + x]; };
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      // the depth camera sees the scene shifted relative to the colour camera
      const int sx = x - m.color_offset_px;
      float z = (sx >= 0 && sx < w) ? at(sx, y) : 0.0f;
      float& out = depth.depth_m[static_cast<size_t>(y) * w + x];
      if (!(z > m.min_range_m && z < m.max_range_m) || sx <= 0 || sx >= w - 1 || y == 0 || y == h - 1) {
        out = 0.0f;
        continue;
      }
      // silhouettes: a large relative jump to a neighbour
      const float n[4] = {at(sx - 1, y), at(sx + 1, y), at(sx, y - 1), at(sx, y + 1)};
      bool edge = false;
      for (const float v : n) edge |= !(v > 0.0f) || std::fabs(v - z) > m.edge_jump * z;
      if (edge && uni(rng) < m.edge_drop) {
        out = 0.0f;
        continue;
      }
      // grazing angle from the depth gradient: normal of the back-projected surface
      if (!edge) {
        const double dzdx = 0.5 * (n[1] - n[0]), dzdy = 0.5 * (n[3] - n[2]);
        const double px = z / k.fx, py = z / k.fy;  // metres per pixel at this depth
        const double gx = dzdx / px, gy = dzdy / py;
        const double u = (x - k.cx) / k.fx, v = (y - k.cy) / k.fy;
        // normal ~ (-gx, -gy, 1) in camera space; cosine with the viewing ray (u, v, 1)
        const double nx = -gx, ny = -gy, nz = 1.0;
        const double c = std::fabs(nx * u + ny * v + nz) / (std::sqrt(nx * nx + ny * ny + nz * nz) * std::sqrt(u * u + v * v + 1.0));
        if (c < m.grazing_cos) {
          out = 0.0f;
          continue;
        }
      }
      double zn = z;
      if (m.noise) zn += (0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)) * gauss(rng);
      // quantise in disparity: d = bf / z rounded to the disparity step
      const double d = std::round(m.baseline_focal / zn / m.disparity_step) * m.disparity_step;
      out = d > 0.0 ? static_cast<float>(m.baseline_focal / d) : 0.0f;
    }
  }
}

}  // namespace artrace::ar
