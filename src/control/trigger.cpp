#include "manip/control/trigger.hpp"

namespace manip::control {

void PerturbationTrigger::arm(double angle_rad, const PerturbationProfile& profile, double direction) {
  armed_ = true;
  angle_ = angle_rad;
  profile_ = profile;
  dir_ = direction >= 0 ? 1.0 : -1.0;
  onset_cycle_ = -1;
}

bool PerturbationTrigger::update(std::int64_t cycle, double x2_m, double xd2_mps) {
  bool onset = false;
  if (armed_ && onset_cycle_ < 0 && have_prev_) {
    const bool crossed = dir_ * (prev_x2_ - trigger_) < 0.0 && dir_ * (x2_m - trigger_) >= 0.0;
    if (crossed && dir_ * xd2_mps > 0.0) {
      onset_cycle_ = cycle;
      armed_ = false;  // once per arming
      onset = true;
    }
  }
  prev_x2_ = x2_m;
  have_prev_ = true;
  return onset;
}

bool PerturbationTrigger::active(std::int64_t cycle) const {
  if (onset_cycle_ < 0 || cycle < onset_cycle_) return false;
  return static_cast<double>(cycle - onset_cycle_) * dt_ < profile_.duration_s;
}

Vec2 PerturbationTrigger::force_shoulder_n(std::int64_t cycle) const {
  if (!active(cycle)) return Vec2::Zero();
  return profile_.force_n(static_cast<double>(cycle - onset_cycle_) * dt_, angle_);
}

}  // namespace manip::control
