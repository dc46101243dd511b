#pragma once
// The impedance along the push: what one perturbation direction determines.
//
// Three pushes in one direction u cannot determine a full 2x2 D and K (the
// response hardly excites the perpendicular axis, so half the parameters are
// unconstrained: pem at 30° gave K22 = 10 067 ± 953 N/m, truth 314). What
// they do determine is the 1-D impedance along u: per trial,
//   uᵀ(Δu_ext - M_BSP Δẍ) = d_u · uᵀΔẋ + k_u · uᵀΔx      (least squares)
// whose d_u, k_u approximate uᵀDu, uᵀKu (exact when the response stays on
// u; the cross terms uᵀDw, uᵀKw with the perpendicular w are small when it
// nearly does). Reported as the mean over the angle's trials with the
// Student-t 95 % interval of that mean: the trial-to-trial spread is the
// honest uncertainty (the within-trial residuals are correlated, so a
// least-squares SE would be far too narrow).
#include <limits>
#include <span>
#include <vector>

#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

struct DirectionalEstimate {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double angle_deg{kNaN};
  Vec2 u{Vec2::Zero()};           // push direction, shoulder frame
  int n_trials{0};
  double d_nspm{kNaN}, k_npm{kNaN};      // mean over trials of uᵀDu, uᵀKu
  double d_std{kNaN}, k_std{kNaN};       // sample std over trials (n - 1)
  double d_lo{kNaN}, d_hi{kNaN}, k_lo{kNaN}, k_hi{kNaN};  // 95 % interval of the mean (n >= 2)
  std::vector<double> d_trials, k_trials;  // per-trial fits
  double d_true{kNaN}, k_true{kNaN};     // uᵀD_true u, uᵀK_true u (simulated logs)
};

// The 1-D fit above over `windows` (one angle), with M_BSP per window.
// Throws std::invalid_argument if no window has enough samples.
DirectionalEstimate fit_directional(std::span<const VariationalWindow> windows, std::span<const Mat2> m_bsp,
                                    ForceSource force, double angle_deg);

}  // namespace manip::estimation
