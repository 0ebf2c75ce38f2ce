#include "artrace/ar/depth_registration.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace artrace::ar {

std::string DepthShiftEstimate::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "depth shift %+d,%+d px (colour step across the depth's edges %.1f there, %.1f unshifted, %.1f two pixels off; %lld "
                "depth discontinuities)%s",
                best.dx, best.dy, score, score_zero, score_ring, discontinuities, confident ? "" : ": no clear peak, no shift applied");
  return buf;
}

DepthShiftEstimate estimate_depth_shift(const std::vector<const SensorFrame*>& frames, const DepthShiftOptions& options) {
  const int r = std::max(0, options.max_shift);
  const int side = 2 * r + 1;
  std::vector<double> sum(static_cast<size_t>(side) * side, 0.0);
  std::vector<long long> count(sum.size(), 0);
  long long discontinuities = 0;
  for (const SensorFrame* f : frames) {
    const DepthImage& d = f->depth;
    const ColorImage& c = f->color;
    if (d.empty() || c.empty() || d.width != c.width || d.height != c.height) continue;
    const int w = d.width, h = d.height;
    auto step = [&](int x0, int y0, int x1, int y1) {
      const uint8_t* a = c.at(x0, y0);
      const uint8_t* b = c.at(x1, y1);
      return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
    };
    // the discontinuity between depth pixels (x, y) and (x + ex, y + ey)
    auto score = [&](int x, int y, int ex, int ey) {
      ++discontinuities;
      for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
          const int x0 = x - dx, y0 = y - dy, x1 = x0 + ex, y1 = y0 + ey;
          if (x0 < 0 || y0 < 0 || x1 >= w || y1 >= h) continue;
          const size_t i = static_cast<size_t>(dy + r) * side + (dx + r);
          sum[i] += step(x0, y0, x1, y1);
          ++count[i];
        }
      }
    };
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const float z = d.at(x, y);
        if (!DepthImage::valid(z)) continue;
        auto jump = [&](float n) { return DepthImage::valid(n) && std::fabs(n - z) > options.min_jump * std::min(n, z); };
        if (x + 1 < w && jump(d.at(x + 1, y))) score(x, y, 1, 0);
        if (y + 1 < h && jump(d.at(x, y + 1))) score(x, y, 0, 1);
      }
    }
  }
  DepthShiftEstimate e;
  e.discontinuities = discontinuities;
  std::vector<double> mean(sum.size(), 0.0);
  for (size_t i = 0; i < sum.size(); ++i) mean[i] = count[i] > 0 ? sum[i] / static_cast<double>(count[i]) : 0.0;
  const size_t zero = static_cast<size_t>(r) * side + r;
  // ties go to the smaller shift: the candidates in order of |dx| + |dy|, then row-major
  size_t best = zero;
  for (size_t i = 0; i < mean.size(); ++i) {
    const int dx = static_cast<int>(i % side) - r, dy = static_cast<int>(i / side) - r;
    const int bx = static_cast<int>(best % side) - r, by = static_cast<int>(best / side) - r;
    if (mean[i] > mean[best] || (mean[i] == mean[best] && std::abs(dx) + std::abs(dy) < std::abs(bx) + std::abs(by))) best = i;
  }
  const int bx = static_cast<int>(best % side) - r, by = static_cast<int>(best / side) - r;
  double ring_sum = 0.0;
  int ring_n = 0;
  for (size_t i = 0; i < mean.size(); ++i) {
    const int dx = static_cast<int>(i % side) - r, dy = static_cast<int>(i / side) - r;
    if (std::max(std::abs(dx - bx), std::abs(dy - by)) == 2) ring_sum += mean[i], ++ring_n;
  }
  e.score_ring = ring_n > 0 ? ring_sum / ring_n : 0.0;
  e.scores = mean;
  e.max_shift = r;
  e.score = mean[best];
  e.score_zero = mean[zero];
  const bool inside = std::abs(bx) < r && std::abs(by) < r;
  e.confident = discontinuities >= options.min_discontinuities && inside && ring_n > 0 && e.score >= options.min_peak * e.score_ring &&
                (best == zero || e.score >= options.min_margin * e.score_zero);
  if (e.confident) e.shift = {bx, by};
  e.best = {bx, by};
  return e;
}

DepthImage shift_depth(const DepthImage& depth, DepthShift shift) {
  if (shift.zero()) return depth;
  DepthImage out;
  out.width = depth.width;
  out.height = depth.height;
  out.depth_m.assign(depth.depth_m.size(), 0.0f);
  for (int y = 0; y < depth.height; ++y) {
    const int sy = y + shift.dy;
    if (sy < 0 || sy >= depth.height) continue;
    for (int x = 0; x < depth.width; ++x) {
      const int sx = x + shift.dx;
      if (sx >= 0 && sx < depth.width) out.depth_m[static_cast<size_t>(y) * depth.width + x] = depth.at(sx, sy);
    }
  }
  return out;
}

bool DepthShiftedSource::next(SensorFrame& frame) {
  if (!inner_->next(frame)) return false;
  frame.depth = shift_depth(frame.depth, shift_);
  return true;
}

std::string DepthShiftedSource::describe() const {
  return inner_->describe() + " (depth shifted " + std::to_string(shift_.dx) + "," + std::to_string(shift_.dy) + " px)";
}

DepthShiftEstimate estimate_depth_shift(FrameSource& source, int sample_frames, const DepthShiftOptions& options) {
  std::vector<SensorFrame> frames;
  const std::optional<int64_t> n = source.frame_count();
  const int k = std::max(1, sample_frames);
  if (n && *n > 0) {
    int64_t last = -1;
    for (int i = 0; i < k; ++i) {
      const int64_t index = k == 1 ? 0 : static_cast<int64_t>(std::llround(static_cast<double>(i) * (*n - 1) / (k - 1)));
      if (index == last) continue;
      last = index;
      source.seek(index);
      SensorFrame f;
      if (!source.next(f)) break;
      frames.push_back(std::move(f));
    }
  } else {
    SensorFrame f;
    for (int i = 0; i < k && source.next(f); ++i) frames.push_back(f);
  }
  source.rewind();
  std::vector<const SensorFrame*> views;
  for (const SensorFrame& f : frames) views.push_back(&f);
  return estimate_depth_shift(views, options);
}

}  // namespace artrace::ar
