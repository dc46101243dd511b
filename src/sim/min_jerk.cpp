#include "manip/sim/min_jerk.hpp"

#include <algorithm>

namespace manip::sim {

MinJerkSample min_jerk(const Vec2& start, const Vec2& goal, double t0_s, double duration_s, double bow_m,
                       double t_s) {
  MinJerkSample out;
  const double s = std::clamp((t_s - t0_s) / duration_s, 0.0, 1.0);
  const Vec2 d = goal - start;
  const double s2 = s * s, s3 = s2 * s;
  const double inv_t = 1.0 / duration_s;
  // Flash & Hogan 1985: x = x0 + d (10 s^3 - 15 s^4 + 6 s^5)
  out.x = start + d * (10.0 * s3 - 15.0 * s3 * s + 6.0 * s3 * s2);
  out.xd = d * ((30.0 * s2 - 60.0 * s3 + 30.0 * s2 * s2) * inv_t);
  out.xdd = d * ((60.0 * s - 180.0 * s2 + 120.0 * s3) * inv_t * inv_t);
  if (bow_m != 0.0 && d.norm() > 0.0) {
    // Lateral bow 64 s^3 (1-s)^3: zero position, velocity and acceleration at
    // both ends, so it adds no jerk impulse to the plan.
    const Vec2 n = Vec2(-d.y(), d.x()).normalized();
    const double g = s - s2;  // s(1-s)
    const double f = 64.0 * g * g * g;
    const double fp = 64.0 * 3.0 * g * g * (1.0 - 2.0 * s);
    const double fpp = 64.0 * (6.0 * g * (1.0 - 2.0 * s) * (1.0 - 2.0 * s) - 6.0 * g * g);
    out.x += n * (bow_m * f);
    out.xd += n * (bow_m * fp * inv_t);
    out.xdd += n * (bow_m * fpp * inv_t * inv_t);
  }
  return out;
}

}  // namespace manip::sim
