#include "artrace/ar/occlusion.h"

#include "artrace/core/renderer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>

namespace artrace::ar {

namespace {

/// Calls fn(begin, end) on consecutive pieces of [0, n), `piece` items each (the last may be
/// shorter), on `threads` workers (0: every core); n <= piece is one call on the caller's thread,
/// with no task arena. For work whose items are independent: the pieces depend on n and `piece`
/// only, so the result does not depend on the thread count.
void for_pieces(size_t n, size_t piece, int threads, const std::function<void(size_t, size_t)>& fn) {
  if (n <= piece) {
    if (n > 0) fn(0, n);
    return;
  }
  // the pieces as the tiles of a one-row image (core's tile loop: its task arena and thread count)
  core::for_each_tile(static_cast<int>((n + piece - 1) / piece), 1, threads, [&](const core::Tile& t) {
    for (int k = t.x0; k < t.x1; ++k) fn(static_cast<size_t>(k) * piece, std::min(n, static_cast<size_t>(k + 1) * piece));
  }, 1);
}

}  // namespace

DepthImage fill_depth_holes(const DepthImage& depth, int radius, int passes, int max_hole_px, int threads) {
  DepthImage cur = depth;
  const int w = depth.width, h = depth.height;
  if (depth.empty()) return cur;
  // Only small holes are filled: a large region without readings (beyond the sensor's range, a
  // window, a black surface) says nothing about what is there, and filling it from its rim would
  // grow whatever surrounds it. `todo` lists the small holes' pixels. The holes are found as runs
  // along the rows, a run joined to the runs it touches in the row above (union-find, each root
  // holding its hole's size): a pass over the pixels and one step a run, where a flood fill took a
  // queue step a hole pixel.
  struct Run {
    int32_t begin, end;  ///< pixel indices [begin, end) in one row
    int32_t parent;
    int64_t size;  ///< at a root: the pixels of its hole
  };
  std::vector<Run> runs;
  const auto root = [&](int32_t r) {
    while (runs[static_cast<size_t>(r)].parent != r) {
      Run& run = runs[static_cast<size_t>(r)];
      run.parent = runs[static_cast<size_t>(run.parent)].parent;  // path halving
      r = run.parent;
    }
    return r;
  };
  size_t above = 0;  // the first run of the row above
  for (int y = 0; y < h; ++y) {
    const float* row = &depth.depth_m[static_cast<size_t>(y) * w];
    const size_t first = runs.size();
    for (int x = 0; x < w;) {
      if (row[x] > 0.0f) {
        ++x;
        continue;
      }
      const int begin = x;
      while (x < w && !(row[x] > 0.0f)) ++x;
      const int32_t id = static_cast<int32_t>(runs.size());
      runs.push_back(Run{y * w + begin, y * w + x, id, x - begin});
    }
    // join the runs that overlap a run of the row above (4-neighbours), both lists in x order
    for (size_t a = above, b = first; a < first && b < runs.size();) {
      const int32_t a0 = runs[a].begin + w, a1 = runs[a].end + w;  // the run above, moved down a row
      if (a0 < runs[b].end && runs[b].begin < a1) {
        const int32_t ra = root(static_cast<int32_t>(a)), rb = root(static_cast<int32_t>(b));
        if (ra != rb) {
          runs[static_cast<size_t>(rb)].parent = ra;
          runs[static_cast<size_t>(ra)].size += runs[static_cast<size_t>(rb)].size;
        }
      }
      if (a1 < runs[b].end) {
        ++a;
      } else {
        ++b;
      }
    }
    above = first;
  }
  std::vector<int32_t> todo;
  for (size_t k = 0; k < runs.size(); ++k) {
    if (runs[static_cast<size_t>(root(static_cast<int32_t>(k)))].size > max_hole_px) continue;
    for (int32_t i = runs[k].begin; i < runs[k].end; ++i) todo.push_back(i);
  }
  // Each pass gives every pixel still to fill that has valid neighbours a value from the depths
  // the pass began with (so the pixels of a pass are independent, and run side by side).
  std::vector<float> value(todo.size());
  for (int pass = 0; pass < passes && !todo.empty(); ++pass) {
    for_pieces(todo.size(), 1024, threads, [&](size_t begin, size_t end) {
      std::vector<float> window;
      window.reserve(static_cast<size_t>(2 * radius + 1) * (2 * radius + 1));
      for (size_t k = begin; k < end; ++k) {
        const int x = todo[k] % w, y = todo[k] / w;
        window.clear();
        for (int yy = std::max(0, y - radius); yy <= std::min(h - 1, y + radius); ++yy) {
          for (int xx = std::max(0, x - radius); xx <= std::min(w - 1, x + radius); ++xx) {
            const float v = cur.at(xx, yy);
            if (v > 0.0f) window.push_back(v);
          }
        }
        value[k] = 0.0f;
        if (window.empty()) continue;
        // Holes cluster at silhouettes on the background side (the sensor's shadow): lean towards
        // the far values of the neighbourhood rather than its median.
        const size_t pick = window.size() * 3 / 4;
        std::nth_element(window.begin(), window.begin() + static_cast<std::ptrdiff_t>(pick), window.end());
        value[k] = window[pick];
      }
    });
    size_t left = 0;
    for (size_t k = 0; k < todo.size(); ++k) {
      if (value[k] > 0.0f) {
        cur.depth_m[static_cast<size_t>(todo[k])] = value[k];
      } else {
        todo[left++] = todo[k];
      }
    }
    if (left == todo.size()) break;  // nothing filled: nothing will be
    todo.resize(left);
  }
  return cur;
}

std::vector<float> occlusion_alpha(const DepthImage& sensor, const ColorImage& color, const std::vector<float>& zv,
                                   const OcclusionOptions& opt) {
  return occlusion_alpha_filled(fill_depth_holes(sensor, opt.fill_radius, opt.fill_passes, opt.max_hole_px, opt.threads), color, zv, opt);
}

std::vector<float> occlusion_alpha_filled(const DepthImage& filled, const ColorImage& color, const std::vector<float>& zv,
                                          const OcclusionOptions& opt) {
  const int w = filled.width, h = filled.height;
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
  // The weight exp(-|c0 - c1|^2 inv_c - |d|^2 inv_s) as a product of one factor per colour
  // channel's difference and one per offset, each from a table, instead of an exp a neighbour.
  double channel_w[256];
  for (int d = 0; d < 256; ++d) channel_w[d] = std::exp(-static_cast<double>(d * d) * inv_c);
  const int side = 2 * std::max(r, 0) + 1;  // a negative radius leaves every window empty
  std::vector<double> offset_w(static_cast<size_t>(side) * side);
  for (int dy = -r; dy <= r; ++dy) {
    for (int dx = -r; dx <= r; ++dx) offset_w[static_cast<size_t>(dy + r) * side + (dx + r)] = std::exp(-static_cast<double>(dx * dx + dy * dy) * inv_s);
  }
  // Runs of equal alphas along each row: where every row of a pixel's window lies inside a run of
  // its own alpha, nothing in the window differs and the scan below is skipped (the common case:
  // alpha 0 or 1 all around)
  std::vector<int32_t> run_start(alpha.size()), run_end(alpha.size());
  for_pieces(static_cast<size_t>(h), 16, opt.threads, [&](size_t y0, size_t y1) {
    for (size_t y = y0; y < y1; ++y) {
      const size_t row = y * w;
      for (int x = 0; x < w; ++x) run_start[row + x] = x > 0 && alpha[row + x] == alpha[row + x - 1] ? run_start[row + x - 1] : x;
      for (int x = w - 1; x >= 0; --x) run_end[row + x] = x + 1 < w && alpha[row + x] == alpha[row + x + 1] ? run_end[row + x + 1] : x + 1;
    }
  });
  // every pixel on its own (out[i] from alpha alone): rows side by side
  for_pieces(static_cast<size_t>(h), 4, opt.threads, [&](size_t y_begin, size_t y_end) {
    for (int y = static_cast<int>(y_begin); y < static_cast<int>(y_end); ++y) {
      for (int x = 0; x < w; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x;
        if (!std::isfinite(zv[i])) continue;
        const int lo = std::max(0, x - r), hi = std::min(w - 1, x + r);
        bool uniform = true;
        for (int yy = std::max(0, y - r); yy <= std::min(h - 1, y + r) && uniform; ++yy) {
          const size_t j = static_cast<size_t>(yy) * w + x;
          uniform = alpha[j] == alpha[i] && run_start[j] <= lo && run_end[j] > hi;
        }
        if (uniform) continue;
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
            const double wt = channel_w[std::abs(c0[0] - c1[0])] * channel_w[std::abs(c0[1] - c1[1])] * channel_w[std::abs(c0[2] - c1[2])] *
                              offset_w[static_cast<size_t>(dy + r) * side + (dx + r)];
            sum += wt * alpha[j];
            wsum += wt;
          }
        }
        if (wsum > 0.0) out[i] = static_cast<float>(sum / wsum);
      }
    }
  });
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

namespace {

using Pixels = std::vector<std::pair<int, int>>;

/// Visible pixels of `m` with a 4-neighbour (inside the image) for which `other_side` holds.
template <class Pred>
Pixels boundary_pixels(const std::vector<uint8_t>& m, int w, int h, const Pred& other_side) {
  Pixels out;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (!m[static_cast<size_t>(y) * w + x]) continue;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int k = 0; k < 4; ++k) {
        if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
        if (other_side(static_cast<size_t>(ny[k]) * w + nx[k])) {
          out.push_back({x, y});
          break;
        }
      }
    }
  }
  return out;
}

/// Sum over `from` of the distance to the nearest pixel of `to` (`none` each when `to` is empty).
double distance_sum(const Pixels& from, const Pixels& to, double none) {
  double sum = 0.0;
  for (const auto& [x, y] : from) {
    double best = none;
    for (const auto& [tx, ty] : to) best = std::min(best, std::hypot(double(x - tx), double(y - ty)));
    sum += best;
  }
  return sum;
}

std::vector<uint8_t> visible(const std::vector<float>& alpha) {
  std::vector<uint8_t> m(alpha.size());
  for (size_t i = 0; i < alpha.size(); ++i) m[i] = alpha[i] >= 0.5f;
  return m;
}

/// O(m): visible pixels next to a covered, hidden one.
Pixels occlusion_boundary(const std::vector<uint8_t>& m, const std::vector<uint8_t>& covered, int w, int h) {
  return boundary_pixels(m, w, h, [&](size_t j) { return covered[j] && !m[j]; });
}

}  // namespace

std::vector<uint8_t> covered_pixels(const std::vector<float>& zv) {
  std::vector<uint8_t> c(zv.size());
  for (size_t i = 0; i < zv.size(); ++i) c[i] = std::isfinite(zv[i]);
  return c;
}

MaskScore score_mask(const std::vector<float>& alpha, const std::vector<uint8_t>& truth, const std::vector<uint8_t>& covered,
                     int w, int h) {
  MaskScore s;
  const std::vector<uint8_t> est = visible(alpha);
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < est.size(); ++i) {
    inter += est[i] && truth[i];
    uni += est[i] || truth[i];
    s.false_visible += est[i] && !truth[i];
    s.false_hidden += !est[i] && truth[i];
  }
  s.iou = uni ? static_cast<double>(inter) / uni : 1.0;
  const double none = std::hypot(double(w), double(h));
  const Pixels o_truth = occlusion_boundary(truth, covered, w, h), o_est = occlusion_boundary(est, covered, w, h);
  const Pixels f_truth = boundary_pixels(truth, w, h, [&](size_t j) { return !truth[j]; });
  const Pixels f_est = boundary_pixels(est, w, h, [&](size_t j) { return !est[j]; });
  s.truth_boundary_pixels = static_cast<int>(o_truth.size());
  s.boundary_pixels = static_cast<int>(o_truth.size() + o_est.size());
  if (s.boundary_pixels > 0) {
    s.boundary_px = (distance_sum(o_truth, f_est, none) + distance_sum(o_est, f_truth, none)) / s.boundary_pixels;
  }
  // the earlier figure: pixels whose left or upper neighbour differs, estimate to truth only
  auto any_boundary = [&](const std::vector<uint8_t>& m) {
    Pixels b;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const uint8_t v = m[static_cast<size_t>(y) * w + x];
        if ((x > 0 && m[static_cast<size_t>(y) * w + x - 1] != v) || (y > 0 && m[static_cast<size_t>(y - 1) * w + x] != v)) b.push_back({x, y});
      }
    }
    return b;
  };
  const Pixels be = any_boundary(est), bt = any_boundary(truth);
  if (!be.empty() && !bt.empty()) s.outline_boundary_px = distance_sum(be, bt, none) / be.size();
  return s;
}

std::optional<double> occlusion_jitter(const std::vector<float>& previous_alpha, const std::vector<float>& alpha,
                                       const std::vector<uint8_t>& previous_truth, const std::vector<uint8_t>& truth,
                                       const std::vector<uint8_t>& previous_covered, const std::vector<uint8_t>& covered,
                                       int w, int h) {
  const size_t edge = occlusion_boundary(truth, covered, w, h).size();
  if (edge == 0) return std::nullopt;
  size_t unexplained = 0;
  for (size_t i = 0; i < alpha.size(); ++i) {
    if (!covered[i] || !previous_covered[i]) continue;
    const bool est_changed = (alpha[i] >= 0.5f) != (previous_alpha[i] >= 0.5f);
    const bool truth_changed = (truth[i] != 0) != (previous_truth[i] != 0);
    unexplained += est_changed != truth_changed;
  }
  return static_cast<double>(unexplained) / static_cast<double>(edge);
}

}  // namespace artrace::ar
