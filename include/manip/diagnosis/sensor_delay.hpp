#pragma once
// The apparatus' actuation delay read from the force sensor (docs/diagnosis.md,
// "Actuation delay from the force sensor").
//
// In an admittance the stage renders what the sensor reads plus u_pert; with
// an actuation delay τ the stage gets u_pert(t − τ) while the log (and eq. 21)
// has u_pert(t). The isolation I (SG jerk of the position, high-pass, three
// integrations from onset; estimation::isolate_variational) is linear, and
// the admittance M_adm ẍ + D_adm ẋ = f_s + u_pert(t − τ) holds on the whole
// trial, so through it
//   M_adm Δẍ + D_adm Δẋ = Δf_s + I[u_pert(· − τ)],
// and the two routes to Δu_ext disagree by
//   e = Δu_ext(eq. 21) − Δu_ext(sensor) = u_pert − I[u_pert(· − τ)]
// up to the isolation's integration constants (an offset and a slope per
// trial and axis) and a mass the log's M_handle misses (b Δẍ). The person's
// motor noise is in neither side: both routes read the same hand.
// u_pert is a zero-order-held command, so I acts on the held staircase
// (its exact double integral), which to the smoothed kinematics lags the
// logged samples by half a cycle.
//
// Where the stages follow the reference through a PD (manip_rt), eq. 21 on
// the encoder exceeds eq. 21 on the reference x_ref, which the controller
// integrated from f_s + u_pert, by M_adm Δë + D_adm Δė (e = x_ref − x):
// PlanarTrial::tracking_iso, a column with a free coefficient (1 when the
// routes differ by the tracking alone), taken like friction when it removes
// more than a tenth of the residual (docs/diagnosis.md, "Tracking").
//
// Measured on simulated sessions (noise-free and realistic, hidden delay
// 0-4 ms): the fit's residual is 3-4 % of the disagreement and τ sits
// 0.03 ms below the hidden delay at every delay, integration step and noise
// level (0.009 ms at M_adm 20 kg): the simulator's ideal admittance solves
// plant and person together, so the person's inertia takes the share
// (M_x + M_handle) / (M_adm + M_x + M_handle) of each held step at once, and
// τ absorbs that share of half a cycle (with it modelled, |τ − truth| <
// 0.001 ms; not kept, a controller integrates the previous reading). The
// fit used before (e against
// u(t) − u(t − τ) without I, b Δẍ and an offset) left 48 % of a clean
// session's disagreement unexplained and put τ 0.05-0.1 ms low.
// A named actuation delay's correction takes this τ (likelihood_stage.cpp,
// refit_jointly): the kinematic likelihood's own delay scatters by ±0.3 ms,
// and D moves 10-16 % per 0.1 ms of it.
#include <cstdint>
#include <string>

#include "manip/diagnosis/dataset.hpp"

namespace manip::diagnosis {

// Samples of PlanarTrial::u_pert_iso before onset: the delays the fit can
// shift I[u_pert] by (the actuation delay's 20 ms bound, and a margin).
inline constexpr double kSensorDelayMaxS = 0.020;
// The share of the disagreement the fit must explain for τ to be a reading
// (reported as the rig's delay, taken by a named delay's correction): delay
// sessions explain 93-99 %, clean ones ~65-85 %; manip_rt sessions without
// the tracking term 8 % (docs/diagnosis.md, "Tracking").
inline constexpr double kSensorDelayMinShare = 0.5;

struct SensorDelay {
  bool available = false;
  std::string why_not;            // when not available
  double tau_s = 0.0;             // the delay
  double lo_s = 0.0, hi_s = 0.0;  // 95 % bootstrap interval over trials
  double mass_kg = 0.0;           // b, the coefficient of Δẍ (a handle mass the log does not carry, seen by one route)
  double friction_n = 0.0;        // stage friction the sensor does not see (at friction_vs_mps; 0: not in the fit)
  double friction_vs_mps = 0.0;
  double explained_share = 0.0;   // 1 − RMS(residual) / RMS(disagreement), nuisance removed from both
  // Tracking (PlanarTrial::tracking_iso) in the fit: its coefficient (1 when
  // the routes differ by the stages' tracking alone) and the share of the
  // residual it removed at the coarse optimum (0: not in the fit).
  double tracking_coef = 0.0;
  double tracking_share = 0.0;
  // The column on held-out trials: each trial left out in turn, the
  // coefficients fitted on the others with and without the column (each fit
  // at its own τ), 1 − √(SS with / SS without) over the trials left out, and
  // in how many of them the column lowered the residual.
  double tracking_heldout_share = 0.0;
  int tracking_heldout_better = 0;
  int trials = 0;
  int bootstrap = 0;
};

// Fits τ on every planar trial of `d` (PlanarTrial::u_pert_iso, du_ext_adm,
// du_ext_force, dxdd, friction_iso): a coarse grid over [−1 ms, 20 ms] with
// and without a stage-friction column at each v_s of the friction grid, then
// a parabolic refinement; the interval from `bootstrap` resamples of the
// trials (deterministic in `seed`). Not available without a force sensor
// channel that moves, or with fewer than 4 trials.
[[nodiscard]] SensorDelay sensor_delay(const Dataset& d, int bootstrap = 200, std::uint64_t seed = 1);

}  // namespace manip::diagnosis
