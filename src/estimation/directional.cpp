#include "manip/estimation/directional.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "manip/estimation/uncertainty.hpp"

namespace manip::estimation {

DirectionalEstimate fit_directional(std::span<const VariationalWindow> windows, std::span<const Mat2> m_bsp,
                                    ForceSource force, double angle_deg) {
  DirectionalEstimate r;
  r.angle_deg = angle_deg;
  const double a = angle_deg * std::numbers::pi / 180.0;
  r.u = Vec2(std::cos(a), std::sin(a));
  for (std::size_t wi = 0; wi < windows.size(); ++wi) {
    const auto& w = windows[wi];
    const auto& du = force == ForceSource::admittance ? w.du_ext_adm : w.du_ext_force;
    const auto n = static_cast<Eigen::Index>(w.size());
    if (n < 3) continue;
    Eigen::MatrixXd x(n, 2);
    Eigen::VectorXd y(n);
    for (Eigen::Index k = 0; k < n; ++k) {
      const auto i = static_cast<std::size_t>(k);
      y(k) = r.u.dot(du[i] - m_bsp[wi] * w.dxdd[i]);
      x(k, 0) = r.u.dot(w.dxd[i]);
      x(k, 1) = r.u.dot(w.dx[i]);
    }
    const Eigen::Vector2d z = x.colPivHouseholderQr().solve(y);
    if (!z.allFinite()) continue;
    r.d_trials.push_back(z(0));
    r.k_trials.push_back(z(1));
  }
  r.n_trials = static_cast<int>(r.d_trials.size());
  if (r.n_trials == 0) throw std::invalid_argument("directional fit: no trial with enough samples");
  auto stats = [&](const std::vector<double>& v, double& mean, double& sd, double& lo, double& hi) {
    const double n = static_cast<double>(v.size());
    mean = 0;
    for (double x : v) mean += x / n;
    if (v.size() < 2) return;  // one trial: no interval (NaN), honestly
    double s2 = 0;
    for (double x : v) s2 += (x - mean) * (x - mean) / (n - 1.0);
    sd = std::sqrt(s2);
    const double h = t_quantile_975(static_cast<int>(v.size()) - 1) * sd / std::sqrt(n);
    lo = mean - h;
    hi = mean + h;
  };
  stats(r.d_trials, r.d_nspm, r.d_std, r.d_lo, r.d_hi);
  stats(r.k_trials, r.k_npm, r.k_std, r.k_lo, r.k_hi);
  return r;
}

}  // namespace manip::estimation
