#pragma once
// Prediction-error (maximum-likelihood) fit of the variational model with an
// explicit model of the person's own motion and motor noise
// (docs/estimator.md, method `pem`, the default).
//
// Why: the output-error fit (`oe`) treats the motion that the perturbation did
// not cause as a per-trial cubic plus white error. A person's motor noise is a
// coloured force; through the coupled arm + admittance it becomes a
// low-frequency position error that the cubic cannot absorb and that least
// squares weighs as if it were white. Here (Box-Jenkins structure)
//   x(t) = x_u(t) + Δx(t),
//   (M_BSP + M_adm + M_handle) Δẍ + (D + D_adm) Δẋ + K Δx = u_pert        (eq. 19-21 + eq. 9)
//   (M_BSP + M_adm + M_handle) ẍ_u + (D_v + D_adm) ẋ_u + K_v x_u = s + n
//   s̈ = w_s (smooth drive: integrated random walk, intensity q_s)
//   ṅ = −n/τ + w_n (motor noise: Ornstein-Uhlenbeck, std σ_n)
// and positions are measured with white noise of variance r. The person's
// own motion gets its own D_v, K_v: the slow noise-driven motion is shaped by
// delayed voluntary feedback too, which must not leak into the involuntary
// D, K of the perturbation response. A Kalman filter gives the exact Gaussian
// likelihood of the raw positions from shortly before onset to the end of
// the window (causal: nothing after the window leaks in); it is maximised over
// D (full), K (symmetric), D_v, K_v and (q_s, σ_n, τ, r) by Fisher scoring.
#include <span>
#include <vector>

#include "manip/estimation/impedance.hpp"

namespace manip::estimation {

// Where the person's drive and motor noise act (docs/estimator.md):
//   box_jenkins  the perturbation response has D, K; the rest of the motion
//                has its own damping and stiffness D_v, K_v, so delayed
//                voluntary feedback of noise-driven errors cannot leak into D, K
//   armax        the noise drives the same arm as the perturbation
enum class PemStructure { box_jenkins, armax };

// Standard errors: the inverse Fisher information (exact if the noise model
// is right), the sandwich over trials (robust to a wrong noise model; the
// default), or delete-one-trial jackknife (robust, one refit per trial: slow).
enum class PemSe { fisher, sandwich, jackknife };

struct PemSettings {
  PemStructure structure{PemStructure::box_jenkins};
  double t_pre_s{0.10};  // data before onset: lets the filter lock on to the drive
  double t_est_s{0.15};
  int max_iterations{80};
  PemSe se{PemSe::sandwich};
  // Hold the model of the person's own motion at these values and fit D, K
  // only (per-angle summaries: three trials pin D, K in one direction, not
  // the noise model; the session fit's noise model is the better one).
  // (A flag and a value rather than std::optional: GCC 12 reports a false
  // -Wmaybe-uninitialized for optionals of this struct inside aggregates.)
  bool hold_disturbance{false};
  DisturbanceModel fixed_disturbance{};
  // Start the iteration at a neighbouring fit (the profile likelihood's next
  // amplitude, a fold of the same session) instead of the generic arm: the
  // same optimum in a third of the iterations (docs/benchmarks.md, Diagnosis).
  bool warm_start{false};
  // Stop when an accepted step lowers the NLL by less than this [nats] (plus
  // 1e-9 relative). The tail converges linearly (Fisher information, not the
  // Hessian), so the remaining gap is about this much again; 1e-3 nats is
  // still far below the likelihood ratio's resolution (docs/diagnosis.md).
  double tolerance_nats{1e-6};
  Mat2 start_d_nspm{Mat2::Zero()}, start_k_npm{Mat2::Zero()};
  DisturbanceModel start_disturbance{};
};

// Windows as for the output-error fit (make_oe_window with t_pre_s =
// PemSettings::t_pre_s); all windows must have the same length. The Kalman
// gains are shared by all trials, so the inertia is the mean of the windows'
// M_total (M_BSP differs by well under 1 % between trial onsets).
// The fit's window of one trial: make_oe_window with PemSettings' own span.
OeWindow make_pem_window(const SessionInfo& info, const TrialData& trial, const Mat2& m_bsp, const PemSettings& s);

// The noise model at the optimum is returned in ImpedanceEstimate::disturbance.
ImpedanceEstimate fit_prediction_error(std::span<const OeWindow> windows, const PemSettings& s);

// Negative log-likelihood of each window at given D, K and noise model (the
// fit's own likelihood, ½ Σ_k (log det S_k + e_kᵀ S_k⁻¹ e_k), not refitted):
// held-out scoring of a fit on other trials (docs/diagnosis.md, "Likelihood
// check"). The sum over the windows of a fit, at its own optimum, is its
// DisturbanceModel::neg_log_likelihood.
std::vector<double> window_neg_log_likelihood(std::span<const OeWindow> windows, const PemSettings& s, const Mat2& d_nspm,
                                              const Mat2& k_npm, const DisturbanceModel& noise);

}  // namespace manip::estimation
