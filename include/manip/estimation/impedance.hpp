#pragma once
// Impedance fits (paper §3.3) and the project's default output-error method.
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "manip/estimation/variational.hpp"

namespace manip::estimation {

// The person's own motion (everything the perturbation did not cause) as the
// prediction-error method models it (pem.hpp), SI units.
struct DisturbanceModel {
  bool box_jenkins{true};   // structure: box-jenkins, else armax (pem.hpp)
  double drive_psd{0};      // intensity of the smooth drive's second derivative [N^2/s^3]
  double motor_noise_n{0};  // stationary std of the OU motor-noise force per axis [N]
  double motor_tau_s{0};    // its correlation time [s]
  double meas_std_m{0};     // position measurement noise std [m]
  double neg_log_likelihood{0};
  Mat2 d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()};  // dynamics of the person's own motion (box-jenkins)
};

// One estimate of the endpoint impedance with its uncertainty, shoulder-frame axes.
struct ImpedanceEstimate {
  Mat2 m_kg{Mat2::Zero()}, d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()};
  Mat2 m_se{Mat2::Constant(std::numeric_limits<double>::quiet_NaN())};
  Mat2 d_se{Mat2::Constant(std::numeric_limits<double>::quiet_NaN())};
  Mat2 k_se{Mat2::Constant(std::numeric_limits<double>::quiet_NaN())};
  double ci_factor{1.96};          // 95% interval = value +- ci_factor * se
  std::string se_kind;             // "least-squares", "jackknife over trials", "std over trials"
  bool m_estimated{false};
  double residual_rms{0.0};        // [N] for equation error, [m] for output error
  double vaf{0.0};                 // variance accounted for, 0..1
  double condition{0.0};           // of the column-normalised regressor / Jacobian
  int n_samples{0};
  int n_params{0};
  int n_trials{0};
  int iterations{0};
  bool identifiable{true};
  std::string flag;                // why not identifiable / not converged
  std::optional<DisturbanceModel> disturbance;  // prediction-error method only
};

// Flag rule (docs/estimator.md): an estimate is not identifiable when any
// element's SE exceeds 50 % of max(|element|, 10 % of its matrix's Frobenius
// norm), or the regressor's condition number exceeds 1e8.
void flag_identifiability(ImpedanceEstimate& e, double rel_se_threshold = 0.5);

// ---- Equation error on isolated variational signals (eq. 24-32) ----------
enum class StiffnessModel { symmetric, full };
enum class ForceSource { admittance, sensor };  // Δu_ext by eq. 21 or from the force sensor

struct LsOptions {
  StiffnessModel k_model{StiffnessModel::symmetric};  // eq. 30 (paper) or 8 parameters
  bool estimate_m{false};                             // eq. 24-29 instead of M_BSP fixed
  ForceSource force{ForceSource::admittance};
};

// Stacks the windows (one: per-trial; many: pooled) and solves by SVD.
// m_bsp[i] is the a priori inertia for window i (eq. 16; ignored if estimate_m).
ImpedanceEstimate fit_equation_error(std::span<const VariationalWindow> windows, std::span<const Mat2> m_bsp,
                                     const LsOptions& opt);

// ---- Output error (the default; docs/estimator.md) -----------------------
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

// Delete-one-trial jackknife standard error from the leave-one-out estimates
// (Efron's (n−1)/n Σ (θ_i − θ̄)²; trials are the independent units).
Eigen::VectorXd jackknife_se(const std::vector<Eigen::VectorXd>& leave_one_out);

// Student-t 0.975 quantile for `dof` degrees of freedom.
double t_quantile_975(int dof);

}  // namespace manip::estimation
