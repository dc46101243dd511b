#pragma once
// Perturbation trigger (paper §4.2/§5.2): the onset cycle k0 is the first cycle
// in which the measured handle position, in the shoulder frame, has crossed the
// trigger line x2 = trigger (previous sample strictly before it, this sample at
// or beyond it, in the start->goal direction) while the measured velocity
// points towards the goal. Only when armed (a perturbed trial with
// perturbations on), at most once per arming. The force is eq. 22-23 sampled
// at the cycle times relative to onset:
//   u_pert(k) = A u_p((k - k0) / f_s) [cos phi, sin phi],
// so u_pert(k0) = 0 (eq. 22 starts from zero force and zero force rate) and the
// profile runs for T_pert. Never allocates.
#include <cstdint>

#include "manip/common/perturbation.hpp"
#include "manip/common/types.hpp"

namespace manip::control {

class PerturbationTrigger {
 public:
  PerturbationTrigger(double trigger_x2_m, double sample_rate_hz) : trigger_(trigger_x2_m), dt_(1.0 / sample_rate_hz) {}

  // direction: +1 if the goal lies at larger x2 than the start, else -1.
  void arm(double angle_rad, const PerturbationProfile& profile, double direction);
  void disarm() { armed_ = false; }
  // Disarm and forget any previous onset (start of an unperturbed trial).
  void clear() {
    armed_ = false;
    onset_cycle_ = -1;
  }
  // Forget the previous sample (e.g. after a pause); the next update cannot fire.
  void forget_previous() { have_prev_ = false; }

  // Call every cycle with the measured shoulder-frame x2 and its velocity.
  // Returns true exactly in the onset cycle.
  bool update(std::int64_t cycle, double x2_m, double xd2_mps);

  // Perturbation force in the shoulder frame at `cycle` (0 unless within T_pert of onset).
  [[nodiscard]] Vec2 force_shoulder_n(std::int64_t cycle) const;
  [[nodiscard]] bool active(std::int64_t cycle) const;
  [[nodiscard]] bool armed() const { return armed_; }
  [[nodiscard]] bool fired() const { return onset_cycle_ >= 0; }
  [[nodiscard]] std::int64_t onset_cycle() const { return onset_cycle_; }
  [[nodiscard]] double trigger_x2_m() const { return trigger_; }

 private:
  double trigger_;
  double dt_;
  bool armed_{false};
  double dir_{1.0};
  double angle_{0.0};
  PerturbationProfile profile_{};
  std::int64_t onset_cycle_{-1};
  bool have_prev_{false};
  double prev_x2_{0.0};
};

}  // namespace manip::control
