#pragma once
// One estimate of the endpoint impedance with its uncertainty (the result
// type every method returns), and the model of the person's own motion that
// the prediction-error method adds to it.
#include <limits>
#include <optional>
#include <string>

#include "manip/common/types.hpp"

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

}  // namespace manip::estimation
