#include "manip/estimation/summary.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "manip/estimation/uncertainty.hpp"

namespace manip::estimation {

std::string SummaryGroup::label() const {
  return is_session() ? "session" : "angle " + std::to_string(static_cast<int>(std::lround(angle_deg)));
}

// Mean (std) over per-trial estimates, laid out like Table 1.
Summary summarise_trials(const std::string& method, const SummaryGroup& group, const std::vector<const TrialResult*>& rs) {
  Summary s;
  s.method = method;
  s.group = group;
  s.kind = "mean (std) over trials";
  s.n_trials = static_cast<int>(rs.size());
  if (rs.empty()) return s;
  for (const auto* r : rs) {
    s.d_nspm += r->est.d_nspm;
    s.k_npm += r->est.k_npm;
    s.m_kg += r->est.m_kg;
    if (!r->est.identifiable) ++s.n_flagged_trials;
  }
  const double n = static_cast<double>(rs.size());
  s.d_nspm /= n;
  s.k_npm /= n;
  s.m_kg /= n;
  for (const auto* r : rs) {
    s.d_spread += (r->est.d_nspm - s.d_nspm).cwiseAbs2();
    s.k_spread += (r->est.k_npm - s.k_npm).cwiseAbs2();
  }
  const double den = std::max(1.0, n - 1.0);
  s.d_spread = (s.d_spread / den).cwiseSqrt();
  s.k_spread = (s.k_spread / den).cwiseSqrt();
  // 95% interval of the mean over trials.
  const double t = rs.size() > 1 ? t_quantile_975(static_cast<int>(rs.size()) - 1) / std::sqrt(n) : std::numeric_limits<double>::quiet_NaN();
  s.d_lo = s.d_nspm - t * s.d_spread;
  s.d_hi = s.d_nspm + t * s.d_spread;
  s.k_lo = s.k_npm - t * s.k_spread;
  s.k_hi = s.k_npm + t * s.k_spread;
  if (rs.size() < 2) {
    s.identifiable = false;
    s.flag = "a single trial: no spread";
  } else {
    // The same rule as for a single fit, applied to the standard error of the mean.
    ImpedanceEstimate e;
    e.d_nspm = s.d_nspm;
    e.k_npm = s.k_npm;
    e.d_se = s.d_spread / std::sqrt(n);
    e.k_se = s.k_spread / std::sqrt(n);
    flag_identifiability(e);
    if (!e.identifiable) {
      s.identifiable = false;
      s.flag = "standard error of the mean: " + e.flag;
    }
  }
  if (s.n_flagged_trials * 2 > s.n_trials) {
    s.identifiable = false;
    s.flag = std::to_string(s.n_flagged_trials) + " of " + std::to_string(s.n_trials) + " trial fits not identifiable";
  }
  return s;
}

Summary summarise_pooled(const std::string& method, const SummaryGroup& group, const ImpedanceEstimate& e) {
  Summary s;
  s.method = method;
  s.group = group;
  s.kind = "pooled fit (" + e.se_kind + ")";
  s.pooled = true;
  s.n_trials = e.n_trials;
  s.d_nspm = e.d_nspm;
  s.k_npm = e.k_npm;
  s.m_kg = e.m_kg;
  s.d_spread = e.d_se;
  s.k_spread = e.k_se;
  s.d_lo = e.d_nspm - e.ci_factor * e.d_se;
  s.d_hi = e.d_nspm + e.ci_factor * e.d_se;
  s.k_lo = e.k_npm - e.ci_factor * e.k_se;
  s.k_hi = e.k_npm + e.ci_factor * e.k_se;
  s.identifiable = e.identifiable;
  s.flag = e.flag;
  s.disturbance = e.disturbance;
  return s;
}

}  // namespace manip::estimation
