#pragma once
// The simplest simulated person: a constant linear endpoint impedance around a
// minimum-jerk plan, with a feed-forward that makes the plan exact on the
// expected load, delayed voluntary feedback, and motor noise. Used by the
// synthetic sessions of the estimator's accuracy study and as the interim
// human of manip_rt's sim backend. Shoulder frame, SI units.
//
//   h = f_ff + D (xd_plan - xd) + K (x_plan - x)                 intrinsic+reflex, no delay
//       + K_v e(t - delay_v) + D_v ed(t - delay_v)               voluntary, delayed
//       + f_noise                                                 Ornstein-Uhlenbeck motor noise
//   f_ff = (M + M_load) xdd_plan + D_load xd_plan                 expected load = admittance
#include <array>
#include <cstdint>
#include <vector>

#include "manip/common/rng.hpp"
#include "manip/sim/human.hpp"

namespace manip::sim {

struct LinearHumanParams {
  Mat2 m_kg{Mat2::Identity() * 2.0};           // endpoint inertia (constant)
  Mat2 d_nspm{(Mat2() << 10.98, -7.94, -8.54, 6.75).finished()};       // paper Table 1
  Mat2 k_npm{(Mat2() << 110.52, -106.05, -106.05, 313.75).finished()}; // paper Table 1 (symmetrised)
  Mat2 m_load_kg{Mat2::Identity() * 5.0};      // expected load the feed-forward compensates
  Mat2 d_load_nspm{Mat2::Identity() * 15.0};
  double voluntary_delay_s{0.160};             // voluntary feedback starts this long after a deviation
  Mat2 k_voluntary_npm{Mat2::Identity() * 300.0};
  Mat2 d_voluntary_nspm{Mat2::Identity() * 30.0};
  double motor_noise_n{0.0};                   // stationary std of the OU motor-noise force per axis
  double motor_noise_tau_s{0.05};              // OU correlation time
  double sample_rate_hz{4000.0};               // for the delay line
};

class LinearImpedanceHuman final : public HumanModel, public TruthSource {
 public:
  explicit LinearImpedanceHuman(const LinearHumanParams& p);
  void begin_trial(const ReachSpec& reach, std::uint64_t seed) override;
  void endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) override;
  void advance(double dt_s, const Vec2& xdd_hand_mps2) override;
  [[nodiscard]] Vec2 hand_position_m() const override { return x_; }
  [[nodiscard]] Vec2 hand_velocity_mps() const override { return xd_; }
  [[nodiscard]] double time_s() const override { return t_; }
  [[nodiscard]] const LinearHumanParams& params() const { return p_; }
  void endpoint_impedance(Mat2& d_nspm, Mat2& k_npm) const override {
    d_nspm = p_.d_nspm;
    k_npm = p_.k_npm;
  }
  [[nodiscard]] std::string truth_model() const override { return "linear-impedance"; }

 private:
  LinearHumanParams p_;
  ReachSpec reach_;
  double t_{0};
  Vec2 x_{Vec2::Zero()}, xd_{Vec2::Zero()};
  Vec2 noise_{Vec2::Zero()};
  PortableRng rng_;  // motor noise: portable, so a seed reproduces the log with any standard library
  std::vector<std::array<double, 4>> delay_;  // ring of (e, ed) per axis
  std::size_t delay_head_{0};
};

}  // namespace manip::sim
