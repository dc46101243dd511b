#include "manip/common/perturbation.hpp"

#include <cmath>
#include <numbers>

namespace manip {
namespace {
constexpr double kPi = std::numbers::pi;
}

// Closed-form integral of eq. 22 per section (T = T_pert/3, s = local time / T):
//   1: rate 1/2 (1 - cos pi s)      -> u = (t - T/pi sin(pi s)) / 2
//   2: rate cos(pi s)               -> u = T/2 + T/pi sin(pi s)
//   3: rate -1/2 (1 + cos pi s)     -> u = T/2 - (t3 + T/pi sin(pi s)) / 2
// The peak T (1/2 + 1/pi) is reached mid-section 2; dividing by it makes the
// peak of eq. 23 exactly A_pert.
double PerturbationProfile::normalized(double t_s) const {
  if (!(t_s > 0.0) || t_s >= duration_s) return 0.0;
  const double T = duration_s / 3.0;
  const double peak = T * (0.5 + 1.0 / kPi);
  double u;
  if (t_s <= T) {
    u = 0.5 * (t_s - T / kPi * std::sin(kPi * t_s / T));
  } else if (t_s <= 2.0 * T) {
    const double t2 = t_s - T;
    u = 0.5 * T + T / kPi * std::sin(kPi * t2 / T);
  } else {
    const double t3 = t_s - 2.0 * T;
    u = 0.5 * T - 0.5 * (t3 + T / kPi * std::sin(kPi * t3 / T));
  }
  return u / peak;
}

double PerturbationProfile::normalized_rate(double t_s) const {
  if (!(t_s >= 0.0) || t_s > duration_s) return 0.0;
  const double T = duration_s / 3.0;
  const double peak = T * (0.5 + 1.0 / kPi);
  double r;
  if (t_s <= T) {
    r = 0.5 * (1.0 - std::cos(kPi * t_s / T));
  } else if (t_s <= 2.0 * T) {
    r = std::cos(kPi * (t_s - T) / T);
  } else {
    r = -0.5 * (1.0 + std::cos(kPi * (t_s - 2.0 * T) / T));
  }
  return r / peak;
}

Vec2 PerturbationProfile::force_n(double t_s, double angle_rad) const {
  return amplitude_n * normalized(t_s) * Vec2(std::cos(angle_rad), std::sin(angle_rad));  // eq. 23
}

}  // namespace manip
