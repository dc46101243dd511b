// Admittance discretisation (exact zero-order hold) against analytic solutions.
#include <catch2/catch.hpp>

#include <cmath>

#include "manip/control/admittance.hpp"

using manip::Vec2;
using manip::control::Admittance;

namespace {
// Step F from rest: M xdd + D xd = F.
double step_x(double m, double d, double f, double t) { return f / d * (t - m / d * (1.0 - std::exp(-d / m * t))); }
double step_v(double m, double d, double f, double t) { return f / d * (1.0 - std::exp(-d / m * t)); }
// Ramp F = r t from rest (0 for t < 0).
double ramp_x(double m, double d, double r, double t) {
  if (t <= 0) return 0.0;
  const double tau = m / d;
  return r / d * (0.5 * t * t - tau * t + tau * tau * (1.0 - std::exp(-t / tau)));
}
double ramp_v(double m, double d, double r, double t) {
  if (t <= 0) return 0.0;
  const double tau = m / d;
  return r / d * (t - tau * (1.0 - std::exp(-t / tau)));
}
}  // namespace

TEST_CASE("admittance step response equals the analytic solution (exact ZOH)", "[admittance]") {
  const double dt = 1.0 / 4000.0;
  const Vec2 m(5.0, 5.0), d(15.0, 15.0);
  Admittance a(m, d, dt);
  a.reset(Vec2::Zero());
  const Vec2 f(3.0, -7.5);
  double max_rel = 0.0;
  for (int k = 1; k <= 8000; ++k) {  // 2 s, ~6 time constants
    a.step(f);
    const double t = k * dt;
    for (int i = 0; i < 2; ++i) {
      const double xe = step_x(m[i], d[i], f[i], t), ve = step_v(m[i], d[i], f[i], t);
      max_rel = std::max(max_rel, std::abs(a.x()[i] - xe) / std::abs(f[i] / d[i] * 2.0));
      max_rel = std::max(max_rel, std::abs(a.xd()[i] - ve) / std::abs(f[i] / d[i]));
      // eq. 20 holds exactly for the logged triple
      REQUIRE(m[i] * a.xdd()[i] + d[i] * a.xd()[i] == Approx(f[i]).margin(1e-12));
    }
  }
  CHECK(max_rel < 1e-10);
  CHECK(a.xd()[0] == Approx(f[0] / d[0] * (1.0 - std::exp(-6.0))).epsilon(1e-9));  // 6 time constants
}

TEST_CASE("admittance ramp response is bracketed by the analytic ramp and the ramp delayed by one sample", "[admittance]") {
  // The ZOH input f_k = r t_k lies between r (t - T) and r t on each interval,
  // and the admittance's impulse responses (position and velocity) are
  // non-negative, so x_zoh(t) lies between x_ramp(t - T) and x_ramp(t).
  const double dt = 1.0 / 4000.0;
  const Vec2 m(5.0, 2.0), d(15.0, 40.0);
  Admittance a(m, d, dt);
  a.reset(Vec2::Zero());
  const Vec2 r(10.0, 4.0);  // N/s
  double worst = 0.0;
  for (int k = 0; k < 4000; ++k) {
    const double tk = k * dt;
    a.step(r * tk);
    const double t = (k + 1) * dt;
    for (int i = 0; i < 2; ++i) {
      const double hi = ramp_x(m[i], d[i], r[i], t), lo = ramp_x(m[i], d[i], r[i], t - dt);
      REQUIRE(a.x()[i] <= hi + 1e-15);
      REQUIRE(a.x()[i] >= lo - 1e-15);
      REQUIRE(a.xd()[i] <= ramp_v(m[i], d[i], r[i], t) + 1e-15);
      REQUIRE(a.xd()[i] >= ramp_v(m[i], d[i], r[i], t - dt) - 1e-15);
      worst = std::max(worst, std::abs(a.x()[i] - hi));
    }
  }
  // After 1 s the lag of the hold is half a sample: |x - x_ramp| ~ xd * T/2.
  CHECK(worst < 0.5 * dt * ramp_v(5.0, 15.0, 10.0, 1.0) * 1.01);
}

TEST_CASE("admittance without damping integrates a constant force exactly", "[admittance]") {
  const double dt = 1e-3;
  Admittance a(Vec2(2.0, 2.0), Vec2(0.0, 0.0), dt);
  a.reset(Vec2(0.1, 0.0), Vec2(0.0, 0.5));
  for (int k = 0; k < 100; ++k) a.step(Vec2(4.0, 0.0));
  const double t = 100 * dt;
  CHECK(a.x()[0] == Approx(0.1 + 0.5 * 2.0 * t * t).epsilon(1e-12));
  CHECK(a.x()[1] == Approx(0.5 * t).epsilon(1e-12));
  CHECK(a.xd()[0] == Approx(2.0 * t).epsilon(1e-12));
}

TEST_CASE("PD law with feed-forward", "[pd]") {
  manip::control::PdGains g{Vec2(1000, 2000), Vec2(10, 20), Vec2(3, 4), Vec2(1, 2), 1.0};
  const Vec2 f = manip::control::pd_force(g, Vec2(0.01, 0.0), Vec2(0.1, 0.2), Vec2(1.0, -1.0), Vec2(0.0, 0.001),
                                          Vec2(0.0, 0.1), Vec2(2.0, -3.0));
  CHECK(f[0] == Approx(1000 * 0.01 + 10 * 0.1 + 3 * 1.0 + 1 * 0.1 - 2.0));
  CHECK(f[1] == Approx(2000 * -0.001 + 20 * 0.1 + 4 * -1.0 + 2 * 0.2 + 3.0));
}
