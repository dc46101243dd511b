#include "manip/control/admittance.hpp"

#include <cmath>

namespace manip::control {

Admittance::Admittance(const Vec2& m_kg, const Vec2& d_nspm, double dt_s) : m_(m_kg), d_(d_nspm), dt_(dt_s) {
  for (int i = 0; i < 2; ++i) {
    if (d_[i] > 0.0) {
      a_[i] = std::exp(-d_[i] * dt_ / m_[i]);
      tau_term_[i] = m_[i] / d_[i] * (1.0 - a_[i]);
    } else {
      a_[i] = 1.0;
      tau_term_[i] = dt_;
    }
  }
}

void Admittance::reset(const Vec2& x_m, const Vec2& xd_mps) {
  x_ = x_m;
  xd_ = xd_mps;
  xdd_.setZero();
}

void Admittance::step(const Vec2& f_n) {
  for (int i = 0; i < 2; ++i) {
    if (d_[i] > 0.0) {
      const double v_inf = f_n[i] / d_[i];
      const double dv = xd_[i] - v_inf;
      x_[i] += v_inf * dt_ + dv * tau_term_[i];
      xd_[i] = v_inf + dv * a_[i];
    } else {
      const double acc = f_n[i] / m_[i];
      x_[i] += xd_[i] * dt_ + 0.5 * acc * dt_ * dt_;
      xd_[i] += acc * dt_;
    }
    xdd_[i] = (f_n[i] - d_[i] * xd_[i]) / m_[i];
  }
}

}  // namespace manip::control
