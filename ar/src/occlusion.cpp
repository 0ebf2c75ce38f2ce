#include "artrace/ar/occlusion.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace artrace::ar {

DepthImage fill_depth_holes(const DepthImage& depth, int radius, int passes) {
  DepthImage cur = depth;
  const int w = depth.width, h = depth.height;
  std::vector<float> window;
  for (int pass = 0; pass < passes; ++pass) {
    DepthImage next = cur;
    bool changed = false;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        if (cur.at(x, y) > 0.0f) continue;
        window.clear();
        int seen = 0;
        for (int dy = -radius; dy <= radius; ++dy) {
          for (int dx = -radius; dx <= radius; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            ++seen;
            const float v = cur.at(xx, yy);
            if (v > 0.0f) window.push_back(v);
          }
        }
        // at least a quarter of the window must be valid: a large hole stays unknown
        if (window.size() * 4 < static_cast<size_t>(seen)) continue;
        std::nth_element(window.begin(), window.begin() + window.size() / 2, window.end());
        next.depth_m[static_cast<size_t>(y) * w + x] = window[window.size() / 2];
        changed = true;
      }
    }
    cur = std::move(next);
    if (!changed) break;
  }
  return cur;
}

std::vector<float> occlusion_alpha(const DepthImage& sensor, const ColorImage& color, const std::vector<float>& zv,
                                   const OcclusionOptions& opt) {
  const int w = sensor.width, h = sensor.height;
  const DepthImage filled = fill_depth_holes(sensor, opt.fill_radius, opt.fill_passes);
  std::vector<float> alpha(static_cast<size_t>(w) * h, 0.0f);
  for (size_t i = 0; i < alpha.size(); ++i) {
    if (!std::isfinite(zv[i])) continue;
    const float zr = filled.depth_m[i];
    if (!(zr > 0.0f)) {
      alpha[i] = 1.0f;  // the sensor knows nothing here: nothing hides the virtual surface
      continue;
    }
    const double sigma = 0.0012 + 0.0019 * (zr - 0.4) * (zr - 0.4);
    const double band = std::max(opt.min_band_m, opt.band_sigmas * sigma);
    alpha[i] = static_cast<float>(std::clamp(0.5 + (zr - zv[i]) / (2.0 * band), 0.0, 1.0));
  }
  if (!opt.refine || color.width != w || color.height != h) return alpha;

  // Joint bilateral refinement near the boundary only (where alpha is not already uniform).
  std::vector<float> out = alpha;
  const int r = opt.guide_radius;
  const double inv_c = 1.0 / (2.0 * opt.guide_sigma_color * opt.guide_sigma_color);
  const double inv_s = 1.0 / (2.0 * opt.guide_sigma_space * opt.guide_sigma_space);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (!std::isfinite(zv[i])) continue;
      bool mixed = false;
      for (int dy = -r; dy <= r && !mixed; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          if (std::fabs(alpha[static_cast<size_t>(yy) * w + xx] - alpha[i]) > 0.01f) {
            mixed = true;
            break;
          }
        }
      }
      if (!mixed) continue;
      const uint8_t* c0 = color.at(x, y);
      double sum = 0.0, wsum = 0.0;
      for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const size_t j = static_cast<size_t>(yy) * w + xx;
          if (!std::isfinite(zv[j])) continue;
          const uint8_t* c1 = color.at(xx, yy);
          const double dc = (c0[0] - c1[0]) * (c0[0] - c1[0]) + (c0[1] - c1[1]) * (c0[1] - c1[1]) + (c0[2] - c1[2]) * (c0[2] - c1[2]);
          const double wt = std::exp(-dc * inv_c - (dx * dx + dy * dy) * inv_s);
          sum += wt * alpha[j];
          wsum += wt;
        }
      }
      if (wsum > 0.0) out[i] = static_cast<float>(sum / wsum);
    }
  }
  return out;
}

std::vector<uint8_t> exact_visibility(const DepthImage& exact, const std::vector<float>& zv) {
  std::vector<uint8_t> m(zv.size(), 0);
  for (size_t i = 0; i < zv.size(); ++i) {
    if (!std::isfinite(zv[i])) continue;
    const float zr = exact.depth_m[i];
    m[i] = !(zr > 0.0f) || zv[i] < zr;
  }
  return m;
}

MaskScore score_mask(const std::vector<float>& alpha, const std::vector<uint8_t>& truth, int w, int h) {
  MaskScore s;
  size_t inter = 0, uni = 0;
  std::vector<uint8_t> est(alpha.size());
  for (size_t i = 0; i < alpha.size(); ++i) {
    est[i] = alpha[i] >= 0.5f;
    inter += est[i] && truth[i];
    uni += est[i] || truth[i];
    s.false_visible += est[i] && !truth[i];
    s.false_hidden += !est[i] && truth[i];
  }
  s.iou = uni ? static_cast<double>(inter) / uni : 1.0;
  // boundary: pixels with a 4-neighbour of the other value; distance to the nearest truth boundary
  auto boundary = [&](const std::vector<uint8_t>& m) {
    std::vector<std::pair<int, int>> b;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const uint8_t v = m[static_cast<size_t>(y) * w + x];
        const bool edge = (x > 0 && m[static_cast<size_t>(y) * w + x - 1] != v) || (y > 0 && m[static_cast<size_t>(y - 1) * w + x] != v);
        if (edge) b.push_back({x, y});
      }
    }
    return b;
  };
  const auto be = boundary(est), bt = boundary(truth);
  if (!be.empty() && !bt.empty()) {
    double sum = 0.0;
    for (const auto& [x, y] : be) {
      double best = std::numeric_limits<double>::infinity();
      for (const auto& [tx, ty] : bt) best = std::min(best, std::hypot(double(x - tx), double(y - ty)));
      sum += best;
    }
    s.boundary_px = sum / be.size();
  }
  return s;
}

}  // namespace artrace::ar
