#include "manip/estimation/validation.hpp"

#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace manip::estimation {

NrmseCurves nrmse_curves(const std::vector<VariationalWindow>& ws, double t_norm_s, int n_points,
                         const std::string& isolation) {
  NrmseCurves c;
  c.isolation = isolation;
  std::vector<const VariationalWindow*> use;
  for (const auto& w : ws)
    if (!w.dx_true.empty()) use.push_back(&w);
  if (use.empty()) throw std::invalid_argument("no trial carries twin truth (not a simulated log?)");
  c.n_trials = static_cast<int>(use.size());
  const double fs = use.front()->fs_hz;
  for (int i = 1; i <= n_points; ++i) c.dt_s.push_back(t_norm_s * i / n_points);
  for (int s = 0; s < 4; ++s) {
    c.mean[static_cast<std::size_t>(s)].assign(c.dt_s.size(), Vec2::Zero());
    c.std[static_cast<std::size_t>(s)].assign(c.dt_s.size(), Vec2::Zero());
  }
  for (int s = 0; s < 4; ++s) {
    std::vector<std::vector<Vec2>> per_trial;
    for (const auto* w : use) {
      const auto& est = s == 0 ? w->dx : s == 1 ? w->dxd : s == 2 ? w->dxdd : w->du_ext_adm;
      const auto& tru = s == 0 ? w->dx_true : s == 1 ? w->dxd_true : s == 2 ? w->dxdd_true : w->du_ext_true;
      const auto n_norm = std::min(w->size(), static_cast<std::size_t>(std::llround(t_norm_s * fs)) + 1);
      Vec2 peak = Vec2::Zero();
      for (std::size_t k = 0; k < n_norm; ++k) peak = peak.cwiseMax(tru[k].cwiseAbs());
      std::vector<Vec2> curve;
      for (double dt : c.dt_s) {
        const auto n = std::min(w->size(), static_cast<std::size_t>(std::llround(dt * fs)) + 1);
        Vec2 se = Vec2::Zero();
        for (std::size_t k = 0; k < n; ++k) se += (est[k] - tru[k]).cwiseAbs2();
        curve.push_back((se / static_cast<double>(n)).cwiseSqrt().cwiseQuotient(peak));
      }
      per_trial.push_back(curve);
    }
    auto& m = c.mean[static_cast<std::size_t>(s)];
    auto& sd = c.std[static_cast<std::size_t>(s)];
    for (const auto& cv : per_trial)
      for (std::size_t i = 0; i < cv.size(); ++i) m[i] += cv[i] / static_cast<double>(per_trial.size());
    for (const auto& cv : per_trial)
      for (std::size_t i = 0; i < cv.size(); ++i) sd[i] += (cv[i] - m[i]).cwiseAbs2();
    for (auto& v : sd) v = (v / std::max<double>(1.0, static_cast<double>(per_trial.size()) - 1.0)).cwiseSqrt();
  }
  return c;
}

nlohmann::json to_json(const NrmseCurves& c) {
  nlohmann::json j;
  j["dt_s"] = c.dt_s;
  j["n_trials"] = c.n_trials;
  j["isolation"] = c.isolation;
  for (std::size_t s = 0; s < 4; ++s) {
    nlohmann::json sig;
    for (int a = 0; a < 2; ++a) {
      std::vector<double> mv, sv;
      for (std::size_t i = 0; i < c.dt_s.size(); ++i) {
        mv.push_back(c.mean[s][i](a));
        sv.push_back(c.std[s][i](a));
      }
      sig["x" + std::to_string(a + 1)] = {{"mean", mv}, {"std", sv}};
    }
    j[NrmseCurves::kSignals[s]] = sig;
  }
  return j;
}

std::string format_text(const NrmseCurves& c) {
  std::ostringstream o;
  o << "NRMSE at " << c.dt_s.back() * 1000 << " ms, " << c.isolation << " isolation (mean (std) over " << c.n_trials
    << " trials; paper Fig. 4: dx, dxd < 5 %, dxdd < 7.5 %, du_ext < 15 %):\n";
  for (std::size_t s = 0; s < 4; ++s) {
    const auto& m = c.mean[s].back();
    const auto& sd = c.std[s].back();
    o << "  " << std::left << std::setw(7) << NrmseCurves::kSignals[s] << std::right << std::fixed << std::setprecision(2)
      << " x1 " << m(0) * 100 << " % (" << sd(0) * 100 << ")   x2 " << m(1) * 100 << " % (" << sd(1) * 100 << ")\n";
  }
  return o.str();
}

void write_nrmse_plot(const NrmseCurves& /*c*/, const std::string& /*svg_path*/) {
  // Intentionally draws nothing: Fig. 4 is drawn by python/manipplot from
  // validation.json (write_plots / render_plots, report/render.hpp).
}

}  // namespace manip::estimation
