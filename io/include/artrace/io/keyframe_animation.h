// Keyframe animation of BART scenes: Kochanek-Bartels (TCB) splines.
//
// D. Kochanek and R. Bartels, "Interpolating Splines with Local Tension, Continuity, and Bias
// Control", SIGGRAPH 1984; rotations with squad (K. Shoemake, "Animating Rotation with Quaternion
// Curves", SIGGRAPH 1985) whose inner quaternions come from the same TCB weights in log space. The
// conventions (first and last key only shape the end tangents, values held outside, uneven-spacing
// factors) are BART's, as set out in shared/docs/aff-format.md.
#pragma once

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include <string>
#include <vector>

namespace artrace::io {

struct TcbKey {
  double time = 0.0;
  glm::dvec3 value{0.0};  ///< position, scale, or for rotations the axis
  double angle_deg = 0.0; ///< rotations only
  double tension = 0.0, continuity = 0.0, bias = 0.0;
};

/// A vector-valued TCB spline (translation or scale).
class TcbTrack {
 public:
  TcbTrack() = default;
  /// Keys sorted by time; fewer than 4 are padded by repeating the end keys. Empty = no track.
  explicit TcbTrack(std::vector<TcbKey> keys);
  bool empty() const { return keys_.empty(); }
  glm::dvec3 evaluate(double t) const;

 private:
  std::vector<TcbKey> keys_;
};

/// A rotation TCB spline over axis-angle keys, interpolated as quaternions with squad.
class TcbRotationTrack {
 public:
  TcbRotationTrack() = default;
  explicit TcbRotationTrack(std::vector<TcbKey> keys);
  bool empty() const { return quats_.empty(); }
  glm::dquat evaluate(double t) const;

 private:
  std::vector<TcbKey> keys_;
  std::vector<glm::dquat> quats_;  ///< unit, consecutive ones in the same hemisphere
};

/// A `k name { transl / rot / scale }` record.
struct KeyframeAnimation {
  std::string name;
  TcbTrack translation;
  TcbRotationTrack rotation;
  TcbTrack scale;

  /// T(t) R(t) S(t); missing tracks are identity.
  glm::dmat4 transform(double t) const;
};

}  // namespace artrace::io
