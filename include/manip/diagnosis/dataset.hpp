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

struct Segment {
  double t0_s = 0.0;                       // time of sample 0 in the session
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
