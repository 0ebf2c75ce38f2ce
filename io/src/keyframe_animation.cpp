#include "artrace/io/keyframe_animation.h"

#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>

namespace artrace::io {
namespace {

/// BART tracks need 4 keys at least; shorter ones repeat their end keys.
std::vector<TcbKey> padded(std::vector<TcbKey> keys) {
  if (keys.empty()) return keys;
  while (keys.size() < 4) {
    if (keys.size() % 2 == 0) keys.insert(keys.begin(), keys.front());
    else keys.push_back(keys.back());
  }
  return keys;
}

/// The first segment i (1 <= i <= n-3) with t in [t_i, t_{i+1}), and the local parameter. Key
/// times may run backwards in places (a glitch of the robots scene): such segments never match.
bool find_segment(const std::vector<TcbKey>& k, double t, size_t& seg, double& s) {
  const size_t n = k.size();
  if (t <= k[1].time) {
    seg = 1;
    s = 0.0;
    return true;
  }
  if (t >= k[n - 2].time) {
    seg = n - 3;
    s = 1.0;
    return true;
  }
  for (size_t i = 1; i + 2 < n; ++i) {
    if (t >= k[i].time && t < k[i + 1].time) {
      seg = i;
      const double len = k[i + 1].time - k[i].time;
      s = len > 0.0 ? (t - k[i].time) / len : 0.0;
      return true;
    }
  }
  return false;
}

double ratio(double num, double den) { return den > 0.0 ? num / den : 1.0; }

struct TcbWeights {
  double out_prev, out_next;  // leaving key i: weights of (P_i - P_{i-1}) and (P_{i+1} - P_i)
  double in_prev, in_next;    // arriving at key i+1: weights of (P_{i+1} - P_i) and (P_{i+2} - P_{i+1})
};

TcbWeights weights(const std::vector<TcbKey>& k, size_t i) {
  const TcbKey& a = k[i];
  const TcbKey& b = k[i + 1];
  const double fa = ratio(2.0 * (b.time - a.time), b.time - k[i - 1].time);
  const double fb = ratio(2.0 * (b.time - a.time), k[i + 2].time - a.time);
  TcbWeights w;
  w.out_prev = fa * (1 - a.tension) * (1 + a.continuity) * (1 + a.bias) / 2;
  w.out_next = fa * (1 - a.tension) * (1 - a.continuity) * (1 - a.bias) / 2;
  w.in_prev = fb * (1 - b.tension) * (1 - b.continuity) * (1 + b.bias) / 2;
  w.in_next = fb * (1 - b.tension) * (1 + b.continuity) * (1 - b.bias) / 2;
  return w;
}

glm::dvec3 quat_log(const glm::dquat& q) {
  const glm::dvec3 v(q.x, q.y, q.z);
  const double sin_half = glm::length(v);
  if (sin_half < 1e-15) return glm::dvec3(0.0);
  const double half = std::atan2(sin_half, q.w);
  return v * (half / sin_half);
}

glm::dquat quat_exp(const glm::dvec3& v) {
  const double half = glm::length(v);
  if (half < 1e-15) return glm::dquat(1.0, 0.0, 0.0, 0.0);
  const glm::dvec3 axis = v * (std::sin(half) / half);
  return glm::dquat(std::cos(half), axis.x, axis.y, axis.z);
}

glm::dquat slerp_short(const glm::dquat& a, const glm::dquat& b, double s) {
  return glm::normalize(glm::slerp(a, b, s));
}

}  // namespace

TcbTrack::TcbTrack(std::vector<TcbKey> keys) : keys_(padded(std::move(keys))) {}

glm::dvec3 TcbTrack::evaluate(double t) const {
  if (keys_.empty()) return glm::dvec3(0.0);
  size_t i = 0;
  double s = 0.0;
  if (!find_segment(keys_, t, i, s)) return keys_[1].value;
  const glm::dvec3 p0 = keys_[i - 1].value, p1 = keys_[i].value, p2 = keys_[i + 1].value, p3 = keys_[i + 2].value;
  const TcbWeights w = weights(keys_, i);
  const glm::dvec3 out_tangent = w.out_prev * (p1 - p0) + w.out_next * (p2 - p1);
  const glm::dvec3 in_tangent = w.in_prev * (p2 - p1) + w.in_next * (p3 - p2);
  const double s2 = s * s, s3 = s2 * s;
  return (2 * s3 - 3 * s2 + 1) * p1 + (s3 - 2 * s2 + s) * out_tangent + (-2 * s3 + 3 * s2) * p2 +
         (s3 - s2) * in_tangent;
}

TcbRotationTrack::TcbRotationTrack(std::vector<TcbKey> keys) : keys_(padded(std::move(keys))) {
  quats_.reserve(keys_.size());
  for (const TcbKey& k : keys_) {
    const double len = glm::length(k.value);
    glm::dquat q(1.0, 0.0, 0.0, 0.0);
    if (len > 0.0) q = glm::angleAxis(glm::radians(k.angle_deg), k.value / len);
    if (!quats_.empty() && glm::dot(quats_.back(), q) < 0.0) q = -q;
    quats_.push_back(q);
  }
}

glm::dquat TcbRotationTrack::evaluate(double t) const {
  if (quats_.empty()) return glm::dquat(1.0, 0.0, 0.0, 0.0);
  size_t i = 0;
  double s = 0.0;
  if (!find_segment(keys_, t, i, s)) return quats_[1];
  const glm::dquat& q0 = quats_[i - 1];
  const glm::dquat& q1 = quats_[i];
  const glm::dquat& q2 = quats_[i + 1];
  const glm::dquat& q3 = quats_[i + 2];
  const TcbWeights w = weights(keys_, i);
  const glm::dvec3 g_prev = quat_log(glm::inverse(q0) * q1);
  const glm::dvec3 g_mid = quat_log(glm::inverse(q1) * q2);
  const glm::dvec3 g_next = quat_log(glm::inverse(q2) * q3);
  const glm::dvec3 out_tangent = w.out_prev * g_prev + w.out_next * g_mid;
  const glm::dvec3 in_tangent = w.in_prev * g_mid + w.in_next * g_next;
  const glm::dquat a = q1 * quat_exp(0.5 * (out_tangent - g_mid));
  const glm::dquat b = q2 * quat_exp(0.5 * (g_mid - in_tangent));
  return glm::normalize(slerp_short(slerp_short(q1, q2, s), slerp_short(a, b, s), 2.0 * s * (1.0 - s)));
}

glm::dmat4 KeyframeAnimation::transform(double t) const {
  glm::dmat4 m(1.0);
  if (!translation.empty()) m = glm::translate(m, translation.evaluate(t));
  if (!rotation.empty()) m = m * glm::mat4_cast(rotation.evaluate(t));
  if (!scale.empty()) m = glm::scale(m, scale.evaluate(t));
  return m;
}

}  // namespace artrace::io
