#pragma once
// Apparent-impedance truth (issue 11): the constant D, K that best explain the
// exact, noise-free variational response of one perturbed trial, with the
// inertia fixed to the estimator's M_BSP. It is what the paper calls the
// involuntary impedance (intrinsic + whatever feedback acts inside the window),
// so an estimator can be judged against it when reflexes are on; the intrinsic
// truth (TruthSource, the linearisation of muscles and segments) stays beside it.
//
// Derivation (paper eq. 9-21). The variational dynamics of the hand about the
// unperturbed twin, linearised and with constant parameters over the window,
// are (eq. 14 with eq. 16 for the endpoint inertia)
//     M_BSP Δẍ + D Δẋ + K Δx = Δu_ext,
// and on the admittance the external force is not measured but reconstructed
// from the perturbation and the rendered dynamics (eq. 19-20 -> eq. 21):
//     Δu_ext = u_pert - (M_adm + M_handle) Δẍ - D_adm Δẋ.
// Here Δ = perturbed run - unperturbed twin (same seed), taken from the plant's
// exact state, so the only thing not captured by a constant D, K is what the
// person really does (delays, reflexes, time variation). D, K solve, per row i
// of the equation, the linear least-squares problem over the samples of
// [0, T_est] after onset of all perturbed trials of the session
//     min_{D_i., K_i.} Σ_trials Σ_k ( Δu_ext,i - (M_BSP Δẍ)_i - D_i. Δẋ - K_i. Δx )²,
// which is eq. 22-23's equation-error fit applied to exact signals.
// Why pooled and not per trial: one trial is perturbed along one direction, so
// its Δx and Δẋ lie nearly on one line and only K v, D v along that direction
// are identifiable (measured: per-trial K11 off by 50 % with a residual below
// 1e-4 of the force); the pooled estimator fits one D, K over all directions
// for the same reason (paper §3.3), and the truth does the same.
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "manip/common/types.hpp"
#include "manip/sim/ideal_admittance.hpp"

namespace manip::sim {

// The `model` string of the apparent truth's MANIP_TRUTH_IMPEDANCE message.
inline constexpr const char* kApparentTruthModel = "apparent";

struct ApparentImpedance {
  Mat2 m_bsp_kg{Mat2::Zero()};  // fixed, as the estimator's (eq. 16 at onset)
  Mat2 d_nspm{Mat2::Zero()};
  Mat2 k_npm{Mat2::Zero()};
  double rms_residual_n{0.0};   // per-axis RMS of the equation residual (what no constant D, K explains)
  double rms_force_n{0.0};      // RMS of Δu_ext - M_BSP Δẍ, for scale
  int n_samples{0};
};

// Δu_ext by eq. 21 from exact variational accelerations and velocities.
[[nodiscard]] inline Vec2 variational_external_force(const PlantParams& p, const Vec2& u_pert_n, const Vec2& dxd_mps,
                                                     const Vec2& dxdd_mps2) {
  return u_pert_n - (p.m_adm_kg + p.m_handle_kg) * dxdd_mps2 - p.d_adm_nspm * dxd_mps;
}

// One trial's exact variational window over [0, T_est] (shoulder frame).
struct VariationalSamples {
  std::vector<Vec2> dx_m, dxd_mps, dxdd_mps2, du_ext_n;
  Mat2 m_bsp_kg{Mat2::Zero()};  // eq. 16 at this trial's onset
};

// The least-squares fit above over all windows (m_bsp_kg of the result: their
// mean). Empty if there are fewer than 8 samples, a window's signals differ in
// length, or the regressors do not span all four directions (no motion, or a
// single perturbation direction): there is then no D, K to determine.
[[nodiscard]] std::optional<ApparentImpedance> fit_apparent_impedance(std::span<const VariationalSamples> windows);

}  // namespace manip::sim
