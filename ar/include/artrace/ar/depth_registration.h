// The residual shift between a recording's depth map and its colour image.
//
// A Kinect's depth is registered to the colour camera by the driver (or by whoever made the
// recording), and what is left is often a pixel or so: the depth's edges sit beside the colour's.
// The occlusion of a virtual object by a real one then puts its boundary where the depth says, a
// pixel off the edge the eye sees, and the colour-guided refinement cannot always pull it back.
//
// The shift is found from the recording itself: at every depth discontinuity (two neighbouring
// readings more than `min_jump` apart, relative to the nearer) the colour image has an edge too,
// between the same two pixels once the shift is undone. Each candidate shift o in [-r, r]^2 is
// scored by the mean colour difference across the depth discontinuities moved by -o; the best
// integer shift wins. On an image of hard edges a wrong shift by one pixel samples the colour
// beside the edge, so the peak is sharp.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <memory>
#include <string>
#include <vector>

namespace artrace::ar {

/// The depth seen `dx`, `dy` pixels right of and below the colour: the colour pixel (x, y) has its
/// depth at (x + dx, y + dy).
struct DepthShift {
  int dx = 0;
  int dy = 0;
  bool operator==(const DepthShift& o) const { return dx == o.dx && dy == o.dy; }
  bool zero() const { return dx == 0 && dy == 0; }
};

struct DepthShiftEstimate {
  DepthShift shift;          ///< the shift to apply: `best` when confident, else zero
  DepthShift best;           ///< the best-scoring candidate
  double score = 0.0;        ///< mean colour step (sum over R, G, B in 8-bit levels) at the best shift
  double score_zero = 0.0;   ///< the same without a shift
  double score_ring = 0.0;   ///< the mean over the candidates two pixels from the best (the larger of |ddx|, |ddy| is 2)
  long long discontinuities = 0;  ///< depth discontinuities the scores average over
  /// The mean colour step of every candidate, row-major: scores[(dy + r) * (2r + 1) + dx + r].
  std::vector<double> scores;
  int max_shift = 0;  ///< r
  /// Whether the estimate stands: enough discontinuities, the best shift inside the search window
  /// (not on its edge, where the true one may lie beyond), a sharp peak (its colour step at least
  /// `min_peak` times score_ring: blurred edges or a depth not lined up by any one shift give a
  /// broad hill) and, unless it is zero, clearly above the unshifted step. When not, `shift` is zero.
  bool confident = false;
  std::string describe() const;
};

struct DepthShiftOptions {
  int max_shift = 3;             ///< candidates dx, dy in [-max_shift, max_shift]
  double min_jump = 0.1;         ///< a discontinuity: neighbours differ by this fraction of the nearer
  long long min_discontinuities = 200;
  double min_margin = 1.1;       ///< best / unshifted score needed to call a shift
  double min_peak = 1.25;        ///< best / score_ring needed to call any shift, zero included
};

/// Estimated from frames whose colour and depth are the same size (frames without both are skipped).
DepthShiftEstimate estimate_depth_shift(const std::vector<const SensorFrame*>& frames, const DepthShiftOptions& options = {});

/// The depth map moved so that it lines up with the colour: out(x, y) = in(x + dx, y + dy), and no
/// reading (0) where that falls outside.
DepthImage shift_depth(const DepthImage& depth, DepthShift shift);

/// A recording whose frames come with the depth shifted into line with the colour.
class DepthShiftedSource : public FrameSource {
 public:
  DepthShiftedSource(std::unique_ptr<FrameSource> inner, DepthShift shift) : inner_(std::move(inner)), shift_(shift) {}
  std::optional<int64_t> frame_count() const override { return inner_->frame_count(); }
  bool next(SensorFrame& frame) override;
  void seek(int64_t index) override { inner_->seek(index); }
  std::string describe() const override;
  double depth_units_per_metre() const override { return inner_->depth_units_per_metre(); }
  std::string intrinsics_source() const override { return inner_->intrinsics_source(); }
  std::vector<std::string> warnings() const override { return inner_->warnings(); }
  std::optional<std::pair<double, double>> trajectory_span() const override { return inner_->trajectory_span(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  DepthShift shift_;
};

/// Reads up to `sample_frames` frames spread over the recording (from its start when the length is
/// unknown), estimates the shift and rewinds the source.
DepthShiftEstimate estimate_depth_shift(FrameSource& source, int sample_frames = 12, const DepthShiftOptions& options = {});

}  // namespace artrace::ar
