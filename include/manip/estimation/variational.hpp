#pragma once
// Paper §3.1: isolating the feedback response of one perturbed trial.
//   1. Savitzky-Golay jerk of the measured position over the whole trial
//      (order 5, window for -3 dB at 30 Hz; §5.1),
//   2. zero-phase Butterworth high-pass of the jerk (order 5, f_c; §4.3),
//   3. cumulative trapezoid from the onset with zero initial values -> Δẍ, Δẋ, Δx,
//   4. Δu_ext from the admittance model (eq. 21) and, beside it, from the
//      measured handle force: Δu_ext = -(Δf_s + M_handle Δẍ).
#include <span>
#include <string>
#include <vector>

#include "manip/estimation/trial_data.hpp"

namespace manip::estimation {

struct PipelineSettings {
  int sg_order{5};                 // §5.1
  double sg_cutoff_hz{30.0};       // §5.1: window chosen for -3 dB here
  int sg_window{0};                // 0: from sg_cutoff_hz and the log's rate (225 at 4 kHz)
  int hp_order{5};                 // §4.3
  double hp_cutoff_hz{1.0};        // §4.3
  double t_est_s{0.150};           // §5.3
};

// Δ signals over [0, T_est] after onset (n = round(T_est fs) + 1 samples), shoulder frame.
struct VariationalWindow {
  int trial{-1};
  double fs_hz{0};
  double angle_rad{0};
  Vec2 x_onset_m{Vec2::Zero()};
  std::vector<Vec2> dx, dxd, dxdd;   // Δx, Δẋ, Δẍ
  std::vector<Vec2> du_ext_adm;      // eq. 21
  std::vector<Vec2> du_ext_force;    // from the force sensor
  std::vector<Vec2> u_pert;          // applied perturbation
  // Twin differences (simulated logs), else empty: the truth of Fig. 4.
  std::vector<Vec2> dx_true, dxd_true, dxdd_true, du_ext_true;
  [[nodiscard]] std::size_t size() const { return dx.size(); }
};

int sg_window_for(const PipelineSettings& s, double fs_hz);

// Throws std::invalid_argument naming the trial if it is too short for the
// filters or the window, or has no onset.
VariationalWindow isolate_variational(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s);
// The same, given the trial's x2 jerk as principal_axis_jerk() returns it (the
// estimator has it from the PSD): the x2 SG pass is not repeated. Identical
// results; an empty or wrongly sized span is ignored.
VariationalWindow isolate_variational(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s,
                                      std::span<const double> jerk_x2);

// Principal-axis (x2) jerk of a whole trial by the SG filter of the pipeline (for PSDs, Fig. 3).
std::vector<double> principal_axis_jerk(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s);

}  // namespace manip::estimation
