#include "manip/model/arm.hpp"

#include <Eigen/LU>
#include <cmath>
#include <string>

namespace manip {

std::optional<std::string> Anthropometrics::invalid_reason() const {
  const char* seg[2] = {"upper_arm", "forearm"};
  for (int i = 0; i < 2; ++i) {
    const std::string s = seg[i];
    if (!(length_m[i] > 0.0 && std::isfinite(length_m[i]))) return s + ".length_m must be positive";
    if (!(mass_kg[i] > 0.0 && std::isfinite(mass_kg[i]))) return s + ".mass_kg must be positive";
    if (!(com_m[i] >= 0.0 && com_m[i] <= length_m[i])) return s + ".com_m must lie within the segment";
    if (!(inertia_kgm2[i] > 0.0 && std::isfinite(inertia_kgm2[i]))) return s + ".inertia_kgm2 must be positive";
  }
  return std::nullopt;
}

Vec2 TwoLinkArm::elbow_position_m(const Vec2& q) const {
  return a_.length_m[0] * Vec2(std::cos(q(0)), std::sin(q(0)));
}

Vec2 TwoLinkArm::hand_position_m(const Vec2& q) const {
  const double q12 = q(0) + q(1);
  return elbow_position_m(q) + a_.length_m[1] * Vec2(std::cos(q12), std::sin(q12));
}

Mat2 TwoLinkArm::jacobian(const Vec2& q) const {
  const double l1 = a_.length_m[0], l2 = a_.length_m[1];
  const double s1 = std::sin(q(0)), c1 = std::cos(q(0));
  const double s12 = std::sin(q(0) + q(1)), c12 = std::cos(q(0) + q(1));
  Mat2 j;
  j << -l1 * s1 - l2 * s12, -l2 * s12, l1 * c1 + l2 * c12, l2 * c12;
  return j;
}

Mat2 TwoLinkArm::jacobian_dot(const Vec2& q, const Vec2& qd) const {
  const double l1 = a_.length_m[0], l2 = a_.length_m[1];
  const double s1 = std::sin(q(0)), c1 = std::cos(q(0));
  const double s12 = std::sin(q(0) + q(1)), c12 = std::cos(q(0) + q(1));
  const double w1 = qd(0), w12 = qd(0) + qd(1);
  Mat2 jd;
  jd << -l1 * c1 * w1 - l2 * c12 * w12, -l2 * c12 * w12, -l1 * s1 * w1 - l2 * s12 * w12, -l2 * s12 * w12;
  return jd;
}

std::optional<Vec2> TwoLinkArm::inverse_kinematics(const Vec2& x) const {
  const double l1 = a_.length_m[0], l2 = a_.length_m[1];
  const double c2 = (x.squaredNorm() - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
  if (!(c2 > -1.0 && c2 < 1.0)) return std::nullopt;
  const double q2 = std::acos(c2);  // > 0: elbow to the right (right arm)
  const double q1 = std::atan2(x(1), x(0)) - std::atan2(l2 * std::sin(q2), l1 + l2 * c2);
  return Vec2(q1, q2);
}

Mat2 TwoLinkArm::joint_inertia(const Vec2& q) const {
  const double l1 = a_.length_m[0];
  const double m1 = a_.mass_kg[0], m2 = a_.mass_kg[1];
  const double r1 = a_.com_m[0], r2 = a_.com_m[1];
  const double i1 = a_.inertia_kgm2[0], i2 = a_.inertia_kgm2[1];
  const double c2 = std::cos(q(1));
  Mat2 m;
  m(0, 0) = i1 + i2 + m1 * r1 * r1 + m2 * (l1 * l1 + r2 * r2 + 2.0 * l1 * r2 * c2);
  m(0, 1) = i2 + m2 * (r2 * r2 + l1 * r2 * c2);
  m(1, 0) = m(0, 1);
  m(1, 1) = i2 + m2 * r2 * r2;
  return m;
}

Vec2 TwoLinkArm::coriolis(const Vec2& q, const Vec2& qd) const {
  const double h = a_.mass_kg[1] * a_.length_m[0] * a_.com_m[1] * std::sin(q(1));
  return Vec2(-h * (2.0 * qd(0) * qd(1) + qd(1) * qd(1)), h * qd(0) * qd(0));
}

Mat2 TwoLinkArm::endpoint_inertia(const Vec2& q) const {
  const Mat2 jinv = jacobian(q).inverse();
  return jinv.transpose() * joint_inertia(q) * jinv;  // eq. 16
}

std::optional<Mat2> TwoLinkArm::endpoint_inertia_at(const Vec2& x) const {
  const auto q = inverse_kinematics(x);
  if (!q) return std::nullopt;
  return endpoint_inertia(*q);
}

double TwoLinkArm::kinetic_energy(const Vec2& q, const Vec2& qd) const {
  return 0.5 * qd.dot(joint_inertia(q) * qd);
}

}  // namespace manip
