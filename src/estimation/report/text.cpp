#include "manip/estimation/report/text.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::fmt;
using report_detail::mat;
using report_detail::create_output_dir;

std::string format_text(const Report& r, const std::string& log_name) {
  std::ostringstream o;
  o << "manip estimate_impedance: " << log_name << "\n";
  o << "  session " << r.info.session_id << ", participant " << r.info.participant_id << ", source " << r.info.source
    << ", " << r.info.sample_rate_hz << " Hz\n";
  o << "  trials " << r.n_trials << ", perturbed " << r.n_perturbed << ", used " << r.n_used << "; SG window "
    << r.sg_window << ", high-pass " << fmt(r.cutoff_used_hz, 3) << " Hz"
    << (r.settings.cutoff_auto ? " (auto)" : "") << ", T_est " << r.settings.pipeline.t_est_s << " s\n";
  if (r.psd.n_unperturbed > 0)
    o << "  PSD: unperturbed peak " << fmt(r.psd.peak_unperturbed_hz, 3) << " Hz; auto cut-off "
      << fmt(r.psd.cutoff_auto_hz, 3) << " Hz (ratio > " << r.settings.cutoff_auto_threshold_db
      << " dB); perturbed/unperturbed at 1 Hz " << fmt(r.psd.ratio_at_1hz_db, 1) << " dB\n";
  for (const auto& s : r.summaries) {
    if (!s.group.is_session()) continue;
    o << "\n  method " << s.method << ": " << s.kind << ", " << s.n_trials << " trials"
      << (s.identifiable ? "" : "  ** NOT IDENTIFIABLE: " + s.flag + " **") << "\n";
    const bool pooled = s.pooled;
    o << "    Damping D [Ns/m]" << std::string(22, ' ') << "Stiffness K [N/m]\n";
    for (int i = 0; i < 2; ++i) {
      std::ostringstream row;
      for (int j = 0; j < 2; ++j)
        row << std::setw(8) << fmt(s.d_nspm(i, j)) << " (" << std::setw(6) << fmt(s.d_spread(i, j)) << ") ";
      row << "   ";
      for (int j = 0; j < 2; ++j)
        row << std::setw(8) << fmt(s.k_npm(i, j)) << " (" << std::setw(6) << fmt(s.k_spread(i, j)) << ") ";
      o << "    " << row.str() << "\n";
    }
    o << "    (" << (pooled ? "estimate (SE)" : "mean (std)") << "; M_BSP at onset ~ [" << fmt(s.m_kg(0, 0)) << ", "
      << fmt(s.m_kg(0, 1)) << "; " << fmt(s.m_kg(1, 0)) << ", " << fmt(s.m_kg(1, 1)) << "] kg)\n";
    if (pooled)
      o << "    95% CI: D11 [" << fmt(s.d_lo(0, 0)) << ", " << fmt(s.d_hi(0, 0)) << "], K11 [" << fmt(s.k_lo(0, 0))
        << ", " << fmt(s.k_hi(0, 0)) << "], K22 [" << fmt(s.k_lo(1, 1)) << ", " << fmt(s.k_hi(1, 1)) << "]\n";
    if (s.disturbance)
      o << "    person's own motion (" << (s.disturbance->box_jenkins ? "box-jenkins" : "armax") << "): motor noise " << fmt(s.disturbance->motor_noise_n, 3)
        << " N std, tau " << fmt(s.disturbance->motor_tau_s * 1000, 1) << " ms; position noise "
        << fmt(s.disturbance->meas_std_m * 1e6, 2) << " um std\n";
  }
  if (r.truth.available) {
    o << "\n  ground truth (" << r.truth.model << ", mean over " << r.truth.n_trials << " trials): D = ["
      << fmt(r.truth.d_nspm(0, 0)) << ", " << fmt(r.truth.d_nspm(0, 1)) << "; " << fmt(r.truth.d_nspm(1, 0)) << ", "
      << fmt(r.truth.d_nspm(1, 1)) << "], K = [" << fmt(r.truth.k_npm(0, 0)) << ", " << fmt(r.truth.k_npm(0, 1)) << "; "
      << fmt(r.truth.k_npm(1, 0)) << ", " << fmt(r.truth.k_npm(1, 1)) << "]\n";
    for (const auto& s : r.summaries) {
      if (!s.group.is_session()) continue;
      o << "    " << std::left << std::setw(13) << s.method << std::right << " error vs truth: D";
      for (int i = 0; i < 4; ++i) {
        const double t = r.truth.d_nspm(i / 2, i % 2);
        o << " " << fmt(100.0 * (s.d_nspm(i / 2, i % 2) - t) / std::abs(t), 1) << "%";
      }
      o << "  K";
      for (int i : {0, 1, 3}) {
        const double t = r.truth.k_npm(i / 2, i % 2);
        o << " " << fmt(100.0 * (s.k_npm(i / 2, i % 2) - t) / std::abs(t), 1) << "%";
      }
      o << "\n";
    }
  }
  if (!r.trials.empty()) {
    o << "\n  per trial:\n    method    trial angle    D11     D12     D21     D22     K11     K12     K22   VAF  flag\n";
    for (const auto& t : r.trials) {
      o << "    " << std::left << std::setw(9) << t.method << std::right << std::setw(6) << t.trial << std::setw(6)
        << fmt(t.angle_deg, 0);
      for (int i = 0; i < 4; ++i) o << std::setw(8) << fmt(t.est.d_nspm(i / 2, i % 2), 1);
      o << std::setw(8) << fmt(t.est.k_npm(0, 0), 0) << std::setw(8) << fmt(t.est.k_npm(0, 1), 0) << std::setw(8)
        << fmt(t.est.k_npm(1, 1), 0) << std::setw(6) << fmt(t.est.vaf, 2) << "  " << (t.est.identifiable ? "" : "not identifiable") << "\n";
    }
  }
  for (const auto& i : r.issues) o << "  excluded: trial " << i.trial << ": " << i.reason << "\n";
  for (const auto& w : r.warnings) o << "  warning: " << w << "\n";
  return o.str();
}

}  // namespace manip::estimation
