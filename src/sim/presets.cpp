#include "manip/sim/presets.hpp"

#include <stdexcept>

#include "manip/model/arm.hpp"

namespace manip::sim {

void apply_noise(NoiseLevel level, SessionDesign& d, LinearHumanParams& h) {
  const bool all = level == NoiseLevel::realistic;
  d.encoder_resolution_m = (all || level == NoiseLevel::quantisation) ? 1e-6 : 0.0;
  d.force_noise_n = (all || level == NoiseLevel::quantisation) ? 0.05 : 0.0;
  d.reach_duration_jitter_s = (all || level == NoiseLevel::variability) ? 0.25 : 0.0;
  d.lateral_bow_std_m = (all || level == NoiseLevel::variability) ? 0.005 : 0.0;
  h.motor_noise_n = (all || level == NoiseLevel::motor) ? 0.2 : 0.0;
  h.motor_noise_tau_s = 0.05;
}

NoiseLevel parse_noise_level(const std::string& s) {
  if (s == "none") return NoiseLevel::none;
  if (s == "realistic") return NoiseLevel::realistic;
  if (s == "quantisation") return NoiseLevel::quantisation;
  if (s == "motor") return NoiseLevel::motor;
  if (s == "variability") return NoiseLevel::variability;
  throw std::invalid_argument("noise level must be none, quantisation, motor, variability or realistic, not '" + s + "'");
}

LinearHumanParams table1_person() {
  LinearHumanParams p;
  // The endpoint inertia the estimator will assume (M_BSP at the trigger
  // point, eq. 16) so that the study measures D and K, not an inertia mismatch.
  p.m_kg = *TwoLinkArm(Anthropometrics{}).endpoint_inertia_at(Vec2(0.0, 0.40));
  return p;
}

LinearHumanParams stiff_person() {
  LinearHumanParams p = table1_person();
  p.d_nspm << 20.0, -6.0, -6.0, 14.0;
  p.k_npm << 300.0, -120.0, -120.0, 600.0;
  return p;
}

}  // namespace manip::sim
