#include "manip/sim/presets.hpp"

#include <stdexcept>

#include "manip/model/arm.hpp"

namespace manip::sim {

void apply_noise(NoiseLevel level, SessionDesign& d, LinearHumanParams& h) {
  if (level == NoiseLevel::none) {
    d.encoder_resolution_m = 0.0;
    d.force_noise_n = 0.0;
    d.reach_duration_jitter_s = 0.0;
    d.lateral_bow_std_m = 0.0;
    h.motor_noise_n = 0.0;
  } else {
    d.encoder_resolution_m = 1e-6;
    d.force_noise_n = 0.05;
    d.reach_duration_jitter_s = 0.25;
    d.lateral_bow_std_m = 0.005;
    h.motor_noise_n = 0.2;
    h.motor_noise_tau_s = 0.05;
  }
}

NoiseLevel parse_noise_level(const std::string& s) {
  if (s == "none") return NoiseLevel::none;
  if (s == "realistic") return NoiseLevel::realistic;
  throw std::invalid_argument("noise level must be 'none' or 'realistic', not '" + s + "'");
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
