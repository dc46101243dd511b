#pragma once
// Generator of synthetic single-joint position-perturbation records with a
// known intrinsic impedance and at most ONE hidden mechanism, for the tests
// and the detection study (docs/diagnosis.md). Independent of the engine's
// regressors: the actuator and the reflex dynamics are integrated in
// continuous time (RK4 at dt/10) from the true kinematics, not built from
// Savitzky-Golay derivatives or the engine's discretised filters.
#include <cstdint>
#include <string>

#include "manip/diagnosis/single_joint.hpp"

namespace manip::diagnosis::synthetic {

enum class Hidden { none, reflex, quadratic_stiffness, offset_drift, friction, torque_lag, relaxation };
[[nodiscard]] const char* name(Hidden h);          // "none", "stretch_reflex", ... (the engine's ids)
[[nodiscard]] const char* main_param_name(Hidden h);  // "delay", "K2", "drift_rate", "Fc", "lag", "tau_relax"

struct Options {
  Hidden hidden = Hidden::none;
  // Hidden term's RMS torque as a fraction of the intrinsic (I, B, K) torque's RMS.
  double magnitude = 0.15;
  // torque_lag only: > 0 sets the lag itself instead of the magnitude (s).
  double lag_s = 0.0;
  double duration_s = 60.0;
  double dt_s = 0.001;
  std::uint64_t seed = 1;
};

struct Truth {
  double I = 0, B = 0, K = 0, c = 0;  // kg m^2, N m s/rad, N m/rad, N m (joint torque convention)
  int torque_sign = 1;                // sign applied when writing (-1: reaction torque, like the lab's records)
  // reflex: gain * LP[ max(dir * v(t - delay), 0) ] * dir ; LP = wn^2 / (s^2 + 2 zeta wn s + wn^2)
  double delay_s = 0, fn_hz = 0, zeta = 0, reflex_gain = 0;
  int reflex_dir = 1;
  double K2 = 0;          // N m/rad^2 about the mean position
  double drift_rate = 0;  // N m/s
  double Fc = 0;          // N m, friction Fc tanh(v / v_s)
  double v_s = 0;         // rad/s
  // torque_lag: the recorded torque is the joint torque through 1 / (1 + lag s)
  // (exact first-order-hold discretisation of the continuous lag).
  double lag_s = 0;
  // relaxation: dK (x_c - LP[x_c]), LP = 1 / (1 + tau_relax s), x_c about the mean position
  double tau_relax_s = 0, dK = 0;
  double noise_white_nm = 0, noise_coloured_nm = 0;
  [[nodiscard]] double main_param(Hidden h) const;
};

struct Generated {
  SingleJointRecord record;
  Truth truth;
};

[[nodiscard]] Generated generate(const Options& opt);
// "# dt=..." header and two columns, or time_s,pos_rad,torque_nm with a header line.
void write_csv(const SingleJointRecord& rec, const std::string& path, bool with_time_column);

}  // namespace manip::diagnosis::synthetic
