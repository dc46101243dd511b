#pragma once
// Model-based isolation of the variational dynamics (an alternative to the
// paper's §3.1 high-pass isolation, which stays available unchanged in
// variational.hpp and is the estimator's `--method paper` front end).
//
// Idea: the response to the perturbation is the response of the arm on the
// admittance to a *known* force, while what corrupts the paper's isolation (the
// unperturbed movement's own high-frequency content: motor noise, path
// variation) is not. So the session's variational model
//   (M_BSP + M_adm + M_handle) Δẍ + (D + D_adm) Δẋ + K Δx = u_pert            (eq. 14 + 20)
// is first fitted to all perturbed trials of the log by the estimator's default
// prediction-error method (fit_prediction_error, pem.hpp: one D, K per session;
// `session_fit: oe` uses the output-error fit with a per-trial cubic instead),
// and then, per trial:
//   1. (optional, off by default) D and K are refined on that trial alone by a few Gauss-Newton
//      steps, ridge-regularised towards the session values (`refine_ridge`), so a
//      trial whose response differs (reflexes, posture) is followed without
//      fitting its noise;
//   2. Δx, Δẋ, Δẍ are the model's response to the logged u_pert (exact zero-order-
//      hold discretisation, so Δẍ = M_tot⁻¹ (u_pert − (D + D_adm) Δẋ − K Δx) at each
//      sample, with no numerical differentiation of the 1 µm-quantised position);
//   3. Δu_ext by eq. 21 from those signals (it then equals M_BSP Δẍ + D Δẋ + K Δx:
//      no 5.3 kg × Δẍ-error amplification).
// Uses the perturbed log alone (never the MANIP_TRUTH_* twins: the twin
// differences are copied into the windows only for validation).
#include <string>
#include <vector>

#include "manip/estimation/impedance.hpp"
#include "manip/estimation/pem.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

struct ModelIsolationSettings {
  enum class SessionFit { pem, oe };
  SessionFit session_fit{SessionFit::pem};  // the estimator's default method, or oe
  PemSettings pem{};          // the pem session fit (SE ignored)
  OeSettings oe{};            // window and polynomial of the oe session fit, and the response window
  PipelineSettings pipeline{};  // only for the paper-isolated windows the truth is copied from
  // Leave-one-trial-out: each trial's response comes from the D, K fitted to the
  // other trials only (an out-of-sample check; N + 1 fits instead of 1).
  bool leave_one_out{false};
  // Per-trial refinement (off by default: measured on simulated sessions it follows
  // each trial's motor noise and is 2-5x worse than the session model; docs/simulation.md).
  bool refine_per_trial{false};
  int refine_iterations{3};
  // Ridge towards the session D, K in units of the session fit's per-trial
  // information (diag of JᵀJ of this trial): 0 = a free per-trial fit.
  double refine_ridge{1.0};
};

struct ModelIsolation {
  Mat2 d_session_nspm{Mat2::Zero()}, k_session_npm{Mat2::Zero()};
  // Model-isolated dx, dxd, dxdd, du_ext_adm (eq. 21), twin truth if any; du_ext_force
  // is left as the paper's isolation computed it (from the force sensor).
  std::vector<VariationalWindow> windows;
  std::vector<Mat2> d_trial_nspm, k_trial_npm;  // per window: the D, K whose response it is
  std::vector<TrialIssue> issues;
};

// Model response over an OeWindow (index 0 = window start, onset at
// w.onset_offset): position, velocity and acceleration at each sample.
struct ModelResponse {
  std::vector<Vec2> x, xd, xdd;
};
ModelResponse simulate_variational_states(const OeWindow& w, const Mat2& d_nspm, const Mat2& k_npm);

// Isolates every perturbed trial (with an onset) of `trials`; trials that cannot
// be used are listed in `issues`. Throws std::invalid_argument if none can.
ModelIsolation isolate_model_based(const SessionInfo& info, const std::vector<TrialData>& trials,
                                   const ModelIsolationSettings& s);

// Reads a log and runs isolate_model_based on its perturbed trials.
ModelIsolation isolate_model_based_log(const std::string& path, const ModelIsolationSettings& s);

}  // namespace manip::estimation
