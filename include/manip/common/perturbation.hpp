#pragma once
// Perturbation force profile with a sinusoidal jerk (paper eq. 22-23).
// The normalised jerk du_p/dt over three sections of T_p = T_pert/3 integrates
// to a force that rises smoothly to 1, returns smoothly to 0, with zero force
// rate at both ends. We evaluate the closed-form integral of eq. 22 (normalised
// so that the peak is exactly 1), not a numerical integral.
#include "manip/common/types.hpp"

namespace manip {

struct PerturbationProfile {
  double duration_s{0.15};   // T_pert
  double amplitude_n{15.0};  // A_pert

  // Normalised force u_p(t) in [0, 1], t since onset; 0 outside [0, T_pert].
  [[nodiscard]] double normalized(double t_s) const;
  // Normalised force rate (eq. 22, scaled so that u_p peaks at 1) [1/s].
  [[nodiscard]] double normalized_rate(double t_s) const;
  // Force vector of eq. 23 at angle phi (counter-clockwise from +x1) [N].
  [[nodiscard]] Vec2 force_n(double t_s, double angle_rad) const;
};

}  // namespace manip
