#pragma once
// Output error: the variational model simulated through the measured
// positions (docs/estimator.md, methods `oe` and `oe-trial`; its windows are
// also the prediction-error method's, pem.hpp).
#include <span>
#include <vector>

#include <Eigen/Dense>

#include "manip/estimation/estimate.hpp"
#include "manip/estimation/trial_data.hpp"

namespace manip::estimation {

// ---- Output error (methods oe, oe-trial; the default is pem, pem.hpp) ----
// One fit of the variational model through all perturbed trials of a session,
// from shortly before onset to the end of the window only (nothing after the
// window can leak in), with a per-trial polynomial absorbing the unperturbed
// movement. The variational model is the arm on the ideal admittance:
//   (M_BSP + M_adm + M_handle) Δẍ + (D + D_adm) Δẋ + K Δx = u_pert
// discretised exactly for the zero-order-held u_pert of the log.
struct OeSettings {
  double t_pre_s{0.05};     // data before onset (anchors the polynomial)
  double t_est_s{0.15};
  int poly_order{3};
  int max_iterations{60};
  bool jackknife{true};     // SE from delete-one-trial refits (honest for correlated residuals)
  // Prediction-error refinement: after a first fit, an AR(p) model of the
  // residuals (Yule-Walker, pooled over trials and axes) whitens residuals in
  // a second fit, so coloured process noise (motor noise) weighs less. 0 = off.
  int prewhiten_order{0};
};

struct OeWindow {
  int trial{-1};
  double fs_hz{0};
  int onset_offset{0};      // index of onset within the window
  Mat2 m_total_kg{Mat2::Zero()};  // M_BSP + M_adm + M_handle
  Mat2 m_bsp_kg{Mat2::Zero()};
  Mat2 d_adm_nspm{Mat2::Zero()};
  std::vector<Vec2> x_m;    // measured position (raw, no filtering)
  std::vector<Vec2> u_n;    // perturbation force command
};

OeWindow make_oe_window(const SessionInfo& info, const TrialData& trial, const Mat2& m_bsp, const OeSettings& s);
ImpedanceEstimate fit_output_error(std::span<const OeWindow> windows, const OeSettings& s);
// Simulated Δx of one window for given D, K (exposed for tests and plots).
std::vector<Vec2> simulate_variational(const OeWindow& w, const Mat2& d_nspm, const Mat2& k_npm);
// The exact zero-order-hold discretisation behind it: state (Δx, Δẋ),
// z[k+1] = phi z[k] + gam u[k] at the window's sample rate.
struct VariationalZoh {
  Eigen::Matrix4d phi;
  Eigen::Matrix<double, 4, 2> gam;
};
VariationalZoh discretise_variational(const OeWindow& w, const Mat2& d_nspm, const Mat2& k_npm);

}  // namespace manip::estimation
