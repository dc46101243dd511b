#pragma once
// The diagnosis engine's input: "a dataset of segments with regressors",
// independent of where the data came from. A front end (single-joint CSV
// records today; manipulandum sessions later, one segment per trial) fills
// it with
//   - the target y (what the model predicts: joint torque, or Δu),
//   - the baseline model's regressor columns (linear in their parameters),
//   - the kinematic signals mechanisms build their regressors from
//     (position, velocity, acceleration of the same smoothed signals),
// all already passed through the same linear smoother, which it also hands
// over so that nonlinear mechanism columns get the identical filtering.
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "manip/dsp/savgol.hpp"

namespace manip::diagnosis {

// One perturbed trial of a planar (manipulandum) session over the estimation
// window [onset, onset + T_est], shoulder frame, as the estimator isolates it
// (paper §3.1, eq. 21): what the planar mechanisms build their columns from.
struct PlanarTrial {
  int trial = -1;
  std::string log;                          // the session log it came from
  double angle_rad = 0.0;
  Eigen::Matrix2d m_bsp = Eigen::Matrix2d::Zero();     // eq. 16 at onset (fixed, as in the estimator)
  Eigen::Matrix2d ws_to_sh = Eigen::Matrix2d::Identity();  // workspace -> shoulder rotation
  // The session's configured admittance and handle mass, shoulder frame
  // (eq. 19-21; for mechanisms that simulate the apparatus).
  Eigen::Matrix2d m_adm = Eigen::Matrix2d::Zero(), d_adm = Eigen::Matrix2d::Zero(), m_handle = Eigen::Matrix2d::Zero();
  std::vector<Eigen::Vector2d> dx, dxd, dxdd;          // Δx, Δẋ, Δẍ (high-pass isolated)
  std::vector<Eigen::Vector2d> du_ext_adm;             // eq. 21
  std::vector<Eigen::Vector2d> du_ext_force;           // from the force sensor
  std::vector<Eigen::Vector2d> u_pert, u_pert_rate;    // logged perturbation force and its rate (N, N/s)
  std::vector<Eigen::Vector2d> xd_stage;               // absolute stage velocity (admittance reference), shoulder frame
  // Stage friction as the isolation leaves it: I[tanh(v_ws / v_s)] per
  // workspace axis, rotated to the shoulder frame, one series per v_s of the
  // stage_friction grid (isolated_stage_friction in manipulandum.hpp).
  std::vector<std::vector<Eigen::Vector2d>> friction_iso;
  // I[u_pert]: the logged force as a zero-order-held staircase, double
  // integrated exactly and isolated as the trial's acceleration is, over
  // [onset − u_pert_iso_pre samples, onset + T_est], integrated from its
  // first sample (sensor_delay.hpp: the actuation delay from the force sensor).
  std::vector<Eigen::Vector2d> u_pert_iso;
  std::size_t u_pert_iso_pre = 0;
  // Tracking: the admittance reference x_ref (aligned to the encoder,
  // estimation::aligned_reference) isolated as x is; tracking_iso is
  // M_adm Δë + D_adm Δė with e = x_ref − x, by which eq. 21 on the encoder
  // exceeds eq. 21 on the reference (sensor_delay.hpp); x_track is e itself
  // over the window, as logged (not isolated: the isolation's integrations
  // turn the force sensor's noise in x_ref into a drift). Empty: no finite
  // reference in the log. reference_shift: 0 or 1 sample (-1: none).
  std::vector<Eigen::Vector2d> tracking_iso, x_track;
  int reference_shift = -1;
};

struct Segment {
  double t0_s = 0.0;                       // time of sample 0 in the session
  // Planar datasets: two segments (one equation per workspace axis) per
  // trial, sharing `group` (the cross-validation and bootstrap unit, so the
  // two axes of a trial are always in the same fold); -1: each segment its own unit.
  int group = -1;
  int axis = -1;                           // 0, 1: row of the 2-D equation (planar only)
  int planar = -1;                         // index into Dataset::planar
  std::vector<double> y;                   // target (smoothed)
  std::vector<double> pos, vel, acc;       // smoothed kinematics and derivatives
  std::vector<double> pos_raw;             // as recorded (for reports)
  std::vector<std::vector<double>> base;   // baseline regressor columns
  std::size_t first = 0, last = 0;         // usable samples [first, last)
};

struct Dataset {
  std::string source;
  double dt_s = 0.0;
  std::shared_ptr<const dsp::SavgolFilter> smoother;  // null: no smoothing
  std::string target_name = "torque", target_unit = "N m", kin_unit = "rad";
  std::vector<std::string> base_names, base_units;
  double pos_ref = 0.0;  // operating point (mean position)
  double smoothing_cutoff_hz = 0.0;  // -3 dB point of the smoother (0: none)
  bool inertia_fixed = false;
  double fixed_inertia = 0.0;
  std::vector<Segment> segments;
  std::vector<PlanarTrial> planar;  // planar (manipulandum) datasets only
  // Planar: the session's apparent D, K (the default method's fit, else the
  // equation-error baseline's), which the short-latency reflex copies with a
  // delay (manipulandum.cpp, PlanarReflex).
  Eigen::Matrix2d planar_ref_d = Eigen::Matrix2d::Zero(), planar_ref_k = Eigen::Matrix2d::Zero();

  [[nodiscard]] bool is_planar() const { return !planar.empty(); }
  [[nodiscard]] std::size_t n_base() const { return base_names.size(); }
  // Smooths x into y with the dataset's smoother (copy when there is none).
  void smooth(const std::vector<double>& x, std::vector<double>& y) const;
};

// Extra regressor columns of a model, [segment][column][sample].
using Columns = std::vector<std::vector<std::vector<double>>>;

struct Fit {
  Eigen::VectorXd theta;  // base parameters then the extra columns' gains
  double sse = 0.0;
  double sst = 0.0;       // sum of squares of y about its mean
  std::size_t n = 0;
};

// Least squares on every usable sample from sample `skip` of each segment on.
[[nodiscard]] Fit fit_full(const Dataset& d, const std::vector<const Columns*>& extras,
                           std::size_t skip = 0);

}  // namespace manip::diagnosis
