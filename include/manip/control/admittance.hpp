#pragma once
// Admittance M_adm xdd_r + D_adm xd_r = f (paper eq. 19-20), per workspace axis
// (M_adm, D_adm diagonal), f = f_sensor + u_pert + wall force.
//
// Discretisation: exact zero-order-hold. The input force measured at t_k is
// held over [t_k, t_k + T] and the linear ODE is solved exactly:
//   a = exp(-D T / M),  v_inf = f / D
//   xd(t_k+T) = v_inf + (xd_k - v_inf) a
//   x(t_k+T)  = x_k + v_inf T + (xd_k - v_inf) (M / D) (1 - a)
// (D = 0: xd += f/M T, x += xd_k T + f/(2M) T^2). The reference is therefore
// exact for piecewise-constant force (step responses match the analytic
// solution to rounding) and deviates from a continuous input only by the hold.
// After step(f) the state is the reference for t_k + T (the PD's set-point for
// the next sample), and xdd() = (f - D xd(t_k+T)) / M, so the logged triple
// satisfies eq. 20 exactly with the logged force.
#include "manip/common/types.hpp"

namespace manip::control {

class Admittance {
 public:
  Admittance(const Vec2& m_kg, const Vec2& d_nspm, double dt_s);

  void reset(const Vec2& x_m, const Vec2& xd_mps = Vec2::Zero());
  void step(const Vec2& f_n);

  [[nodiscard]] const Vec2& x() const { return x_; }
  [[nodiscard]] const Vec2& xd() const { return xd_; }
  [[nodiscard]] const Vec2& xdd() const { return xdd_; }
  [[nodiscard]] const Vec2& m_kg() const { return m_; }
  [[nodiscard]] const Vec2& d_nspm() const { return d_; }
  [[nodiscard]] double dt_s() const { return dt_; }

 private:
  Vec2 m_, d_;
  double dt_;
  Vec2 a_{Vec2::Zero()}, tau_term_{Vec2::Zero()};  // exp(-D T/M), (M/D)(1-a)
  Vec2 x_{Vec2::Zero()}, xd_{Vec2::Zero()}, xdd_{Vec2::Zero()};
};

// High-gain PD per stage with feed-forward (config pd.*):
//   F = Kp (x_r - x) + Kd (xd_r - xd) + m_ff xdd_r + b_ff xd_r - g f_sensor
// The last term cancels the hand's force on the stage (stage: m xdd = F + f_s
// - friction), so the PD only has to correct the residual.
struct PdGains {
  Vec2 kp_npm, kd_nspm, ff_mass_kg, ff_viscous_nspm;
  double ff_sensor_force_gain{1.0};
};

inline Vec2 pd_force(const PdGains& g, const Vec2& x_ref, const Vec2& xd_ref, const Vec2& xdd_ref, const Vec2& x,
                     const Vec2& xd, const Vec2& f_sensor) {
  return g.kp_npm.cwiseProduct(x_ref - x) + g.kd_nspm.cwiseProduct(xd_ref - xd) + g.ff_mass_kg.cwiseProduct(xdd_ref) +
         g.ff_viscous_nspm.cwiseProduct(xd_ref) - g.ff_sensor_force_gain * f_sensor;
}

}  // namespace manip::control
