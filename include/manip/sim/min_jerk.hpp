#pragma once
// Minimum-jerk point-to-point profile (Flash & Hogan 1985), closed form.
#include "manip/common/types.hpp"

namespace manip::sim {

struct MinJerkSample {
  Vec2 x{Vec2::Zero()}, xd{Vec2::Zero()}, xdd{Vec2::Zero()};
};

// Straight min-jerk from start to goal in duration T, starting at t0, plus an
// optional lateral bow: a deviation perpendicular to the path whose profile is
// bow * 16 s^2 (1-s)^2 (zero position, velocity at both ends; peak `bow` mid-way).
MinJerkSample min_jerk(const Vec2& start, const Vec2& goal, double t0_s, double duration_s, double bow_m,
                       double t_s);

}  // namespace manip::sim
