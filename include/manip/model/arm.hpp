#pragma once
// Rigid-body kinematics and dynamics of the two-link planar arm (paper eq. 1,
// 16), in the shoulder frame (docs/conventions.md). q1: shoulder angle from +x1,
// counter-clockwise; q2: elbow angle relative to the upper arm. Right arm with
// the elbow to the right of the shoulder-hand line, i.e. q2 > 0.
#include "manip/common/types.hpp"

#include <optional>
#include <string>

namespace manip {

struct Anthropometrics {
  // Index 0: upper arm, 1: forearm + hand. com: distance of the centre of mass
  // from the proximal joint; inertia: about the centre of mass.
  // Defaults (config/rt.yaml cites them; schema::SessionDescription holds them): lengths Selen, Franklin &
  // Wolpert 2009; masses, centres of mass and inertias Shadmehr & Mussa-Ivaldi 1994.
  double length_m[2]{0.31, 0.34};
  double mass_kg[2]{1.93, 1.52};
  double com_m[2]{0.165, 0.19};
  double inertia_kgm2[2]{0.0141, 0.0188};

  // Empty when valid, else the name of the first bad field and why.
  [[nodiscard]] std::optional<std::string> invalid_reason() const;
};

struct JointState {
  Vec2 q_rad{Vec2::Zero()};
  Vec2 qd_radps{Vec2::Zero()};
};

class TwoLinkArm {
 public:
  explicit TwoLinkArm(const Anthropometrics& a) : a_(a) {}
  [[nodiscard]] const Anthropometrics& params() const { return a_; }

  [[nodiscard]] Vec2 hand_position_m(const Vec2& q) const;
  [[nodiscard]] Vec2 elbow_position_m(const Vec2& q) const;
  [[nodiscard]] Mat2 jacobian(const Vec2& q) const;
  // d/dt J = sum_i dJ/dq_i qd_i
  [[nodiscard]] Mat2 jacobian_dot(const Vec2& q, const Vec2& qd) const;
  // Inverse kinematics, elbow-right branch. Empty if the point is out of reach.
  [[nodiscard]] std::optional<Vec2> inverse_kinematics(const Vec2& x_shoulder_m) const;

  [[nodiscard]] Mat2 joint_inertia(const Vec2& q) const;                   // M_q (eq. 1)
  [[nodiscard]] Vec2 coriolis(const Vec2& q, const Vec2& qd) const;        // C(q, qd) (eq. 1)
  // Endpoint inertia J^-T M_q J^-1 (eq. 16) at hand position x.
  [[nodiscard]] Mat2 endpoint_inertia(const Vec2& q) const;
  [[nodiscard]] std::optional<Mat2> endpoint_inertia_at(const Vec2& x_shoulder_m) const;
  // Kinetic energy 1/2 qd^T M_q qd [J].
  [[nodiscard]] double kinetic_energy(const Vec2& q, const Vec2& qd) const;

 private:
  Anthropometrics a_;
};

}  // namespace manip
