#include "manip/estimation/report/csv.hpp"

#include <cmath>
#include <iomanip>
#include <sstream>

#include "manip/common/output_file.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::element;

namespace {

std::string quote(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c == '\n' ? ' ' : c);
  return q + "\"";
}

// Empty cell for NaN/inf: a typed float column, never the text "nan".
std::string val(double v) {
  if (!std::isfinite(v)) return {};
  std::ostringstream o;
  o << std::setprecision(10) << v;
  return o.str();
}

}  // namespace

std::string csv_text(const std::vector<std::pair<std::string, Report>>& reports) {
  std::ostringstream o;
  o << "log,participant_id,method,is_default,is_biased,level,trial,angle_deg,parameter,quantity,unit,value_si,"
       "ci95_lo_si,ci95_hi_si,spread_si,spread_kind,n_trials,identifiable,flag_reason\n";
  for (const auto& [log, r] : reports) {
    auto row = [&, &log = log, &r = r](const std::string& method, const std::string& level, const std::string& trial,
                                       double angle, const std::string& param, double v, double lo, double hi,
                                       double spread, const std::string& spread_kind, int n, bool ok,
                                       const std::string& flag) {
      const bool is_d = param[0] == 'D';
      o << quote(log) << ',' << quote(r.info.participant_id) << ',' << quote(method) << ','
        << (method == default_method() ? "true" : "false") << ','
        << (method_bias_note(method).empty() ? "false" : "true") << ',' << level << ',' << trial << ',' << val(angle)
        << ',' << param << ',' << (is_d ? "damping" : "stiffness") << ',' << (is_d ? "N s/m" : "N/m") << ',' << val(v)
        << ',' << val(lo) << ',' << val(hi) << ',' << val(spread) << ',' << quote(spread_kind) << ',' << n << ','
        << (ok ? "true" : "false") << ',' << quote(flag) << '\n';
    };
    for (const auto& s : r.summaries) {
      const std::string level = s.group.is_session() ? "session" : "angle";
      const double ang = s.group.is_angle() ? s.group.angle_deg : NAN;
      const std::string sk = s.pooled ? "se" : "std over trials";
      if (s.directional) {
        const auto& d = *s.directional;
        // One trial gives no interval: flagged like the JSON's dir_identifiable.
        const bool ok = d.n_trials >= 2;
        const std::string why = ok ? "" : "one trial at this angle: no interval";
        row(s.method, level, "", ang, "D_dir", d.d_nspm, d.d_lo, d.d_hi, d.d_std, "std over trials", d.n_trials, ok, why);
        row(s.method, level, "", ang, "K_dir", d.k_npm, d.k_lo, d.k_hi, d.k_std, "std over trials", d.n_trials, ok, why);
      }
      for (int i = 0; i < 4; ++i)
        row(s.method, level, "", ang, element("D", i), s.d_nspm(i / 2, i % 2), s.d_lo(i / 2, i % 2), s.d_hi(i / 2, i % 2),
            s.d_spread(i / 2, i % 2), sk, s.n_trials, s.identifiable, s.flag);
      for (int i = 0; i < 4; ++i)
        row(s.method, level, "", ang, element("K", i), s.k_npm(i / 2, i % 2), s.k_lo(i / 2, i % 2), s.k_hi(i / 2, i % 2),
            s.k_spread(i / 2, i % 2), sk, s.n_trials, s.identifiable, s.flag);
    }
    for (const auto& t : r.trials) {
      const auto& e = t.est;
      for (int i = 0; i < 4; ++i) {
        const double v = e.d_nspm(i / 2, i % 2), se = e.d_se(i / 2, i % 2);
        row(t.method, "trial", std::to_string(t.trial), t.angle_deg, element("D", i), v, v - e.ci_factor * se,
            v + e.ci_factor * se, se, e.se_kind, 1, e.identifiable, e.flag);
      }
      for (int i = 0; i < 4; ++i) {
        const double v = e.k_npm(i / 2, i % 2), se = e.k_se(i / 2, i % 2);
        row(t.method, "trial", std::to_string(t.trial), t.angle_deg, element("K", i), v, v - e.ci_factor * se,
            v + e.ci_factor * se, se, e.se_kind, 1, e.identifiable, e.flag);
      }
    }
    if (r.truth.available) {
      for (int i = 0; i < 4; ++i)
        row("truth", "truth", "", NAN, element("D", i), r.truth.d_nspm(i / 2, i % 2), NAN, NAN, NAN, "", r.truth.n_trials,
            true, "");
      for (int i = 0; i < 4; ++i)
        row("truth", "truth", "", NAN, element("K", i), r.truth.k_npm(i / 2, i % 2), NAN, NAN, NAN, "", r.truth.n_trials,
            true, "");
    }
    // The apparent truth (session-level, intrinsic + feedback within the window): method "truth_apparent".
    if (const auto& ap = r.truth.apparent) {
      for (int i = 0; i < 4; ++i)
        row("truth_apparent", "truth", "", NAN, element("D", i), ap->d_nspm(i / 2, i % 2), NAN, NAN, NAN, "", 0, true, "");
      for (int i = 0; i < 4; ++i)
        row("truth_apparent", "truth", "", NAN, element("K", i), ap->k_npm(i / 2, i % 2), NAN, NAN, NAN, "", 0, true, "");
    }
  }
  return o.str();
}

void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path, bool force) {
  write_file_atomically(path, csv_text(reports), force);
}

}  // namespace manip::estimation
