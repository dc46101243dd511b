#pragma once
// The one place where the stages' workspace frame and the arm's shoulder frame
// meet (docs/conventions.md).
//   shoulder frame: origin at the right shoulder, x1 to the participant's right,
//                   x2 forward; the reach runs along x2 from 0.30 to 0.55 m.
//   workspace frame: origin at the centre of the stages' travel (+-0.15 m),
//                   axes along the two stages.
// p_shoulder = R(rot) p_workspace + origin_in_shoulder. Vectors (velocities,
// forces) rotate only.
#include "manip/common/types.hpp"

#include <cmath>

namespace manip {

struct WorkspaceToShoulder {
  Vec2 origin_in_shoulder_m{0.0, 0.425};  // workspace centre in the shoulder frame
  double rot_rad{0.0};

  [[nodiscard]] Mat2 rotation() const {
    const double c = std::cos(rot_rad), s = std::sin(rot_rad);
    Mat2 r;
    r << c, -s, s, c;
    return r;
  }
  [[nodiscard]] Vec2 point_to_shoulder(const Vec2& p_workspace_m) const {
    return rotation() * p_workspace_m + origin_in_shoulder_m;
  }
  [[nodiscard]] Vec2 point_to_workspace(const Vec2& p_shoulder_m) const {
    return rotation().transpose() * (p_shoulder_m - origin_in_shoulder_m);
  }
  [[nodiscard]] Vec2 vector_to_shoulder(const Vec2& v_workspace) const { return rotation() * v_workspace; }
  [[nodiscard]] Vec2 vector_to_workspace(const Vec2& v_shoulder) const {
    return rotation().transpose() * v_shoulder;
  }
};

}  // namespace manip
