#include "manip/sim/linear_human.hpp"

#include <algorithm>
#include <cmath>

#include "manip/sim/min_jerk.hpp"

namespace manip::sim {

LinearImpedanceHuman::LinearImpedanceHuman(const LinearHumanParams& p) : p_(p) {
  const auto n = static_cast<std::size_t>(std::max(1L, std::lround(p_.voluntary_delay_s * p_.sample_rate_hz)));
  delay_.assign(n, {0.0, 0.0, 0.0, 0.0});
}

void LinearImpedanceHuman::begin_trial(const ReachSpec& reach, std::uint64_t seed) {
  reach_ = reach;
  t_ = 0.0;
  x_ = reach.start_shoulder_m;
  xd_.setZero();
  rng_.seed(seed);
  // Start the motor noise in its stationary distribution so trials are alike.
  // Draws in separate statements: argument evaluation order is unspecified and
  // differs between compilers, which would swap the axes' noise.
  const double n1 = rng_.normal();
  const double n2 = rng_.normal();
  noise_ = Vec2(n1, n2) * p_.motor_noise_n;
  for (auto& d : delay_) d = {0.0, 0.0, 0.0, 0.0};
  delay_head_ = 0;
}

void LinearImpedanceHuman::endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) {
  const auto plan = min_jerk(reach_.start_shoulder_m, reach_.goal_shoulder_m, reach_.t_start_s, reach_.duration_s,
                             reach_.lateral_bow_m, t_);
  const Vec2 e = plan.x - x_;
  const Vec2 ed = plan.xd - xd_;
  // Oldest entry of the ring = error one voluntary delay ago.
  const auto& old = delay_[delay_head_];
  const Vec2 e_del(old[0], old[1]);
  const Vec2 ed_del(old[2], old[3]);
  m_x_kg = p_.m_kg;
  h_n = (p_.m_kg + p_.m_load_kg) * plan.xdd + p_.d_load_nspm * plan.xd  // feed-forward on the expected load
        + p_.d_nspm * ed + p_.k_npm * e                                   // involuntary impedance
        + p_.k_voluntary_npm * e_del + p_.d_voluntary_nspm * ed_del       // voluntary, delayed
        + noise_;
}

void LinearImpedanceHuman::advance(double dt_s, const Vec2& xdd_hand_mps2) {
  const auto plan = min_jerk(reach_.start_shoulder_m, reach_.goal_shoulder_m, reach_.t_start_s, reach_.duration_s,
                             reach_.lateral_bow_m, t_);
  const Vec2 e = plan.x - x_;
  const Vec2 ed = plan.xd - xd_;
  delay_[delay_head_] = {e.x(), e.y(), ed.x(), ed.y()};
  delay_head_ = (delay_head_ + 1) % delay_.size();
  // Acceleration held over the step (it is what the plant imposed), position
  // from the mean velocity: exact for constant acceleration. Plain
  // semi-implicit Euler (x += xd_new dt) shifts the response by dt/2 against
  // the force and biased the accuracy study's noise-free D, K by 1-4 % at 16 kHz.
  const Vec2 xd_old = xd_;
  xd_ += xdd_hand_mps2 * dt_s;
  x_ += 0.5 * (xd_old + xd_) * dt_s;
  if (p_.motor_noise_n > 0.0) {
    // Exact Ornstein-Uhlenbeck update: zero-mean, stationary std motor_noise_n.
    const double a = std::exp(-dt_s / p_.motor_noise_tau_s);
    const double b = p_.motor_noise_n * std::sqrt(1.0 - a * a);
    const double n1 = rng_.normal();
    const double n2 = rng_.normal();
    noise_ = a * noise_ + b * Vec2(n1, n2);
  }
  t_ += dt_s;
}

}  // namespace manip::sim
