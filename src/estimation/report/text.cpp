#include "manip/estimation/report/text.hpp"

#include <cmath>
#include <sstream>

#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::element;
using report_detail::fmt;
using report_detail::num;
using report_detail::TextTable;
using report_detail::with_interval;

namespace {

std::string method_label(const std::string& m) {
  return m == default_method() ? m + " (default, recommended)" : (method_bias_note(m).empty() ? m : m + " (BIASED)");
}

}  // namespace

std::string format_text(const Report& r, const std::string& log_name) {
  std::ostringstream o;
  o << "manip estimate_impedance: " << log_name << "\n";
  // A short or foreign log may leave ids empty: say so instead of printing ", ,".
  auto named = [](const std::string& v) { return v.empty() ? std::string("(not given)") : v; };
  o << "  session " << named(r.info.session_id) << ", participant " << named(r.info.participant_id) << ", source "
    << named(r.info.source) << ", " << num(r.info.sample_rate_hz) << " Hz\n";
  o << "  trials " << r.n_trials << ", perturbed " << r.n_perturbed << ", used " << r.n_used << "; SG window "
    << (r.sg_window > 0 ? std::to_string(r.sg_window) : std::string("n/a")) << ", high-pass " << fmt(r.cutoff_used_hz, 3) << " Hz"
    << (r.settings.cutoff_auto ? " (auto)" : "") << ", T_est " << r.settings.pipeline.t_est_s << " s\n";
  if (r.position_used == PositionSource::tracked)
    o << "  positions: the encoder, with the stages' tracking error e = x_ref - x as a known force on the loop "
         "(M_adm Δë + D_adm Δė; --position-source tracked), x_ref aligned by 1 sample in "
      << r.n_reference_shift1 << " trials, by 0 in " << r.n_reference_shift0 << "\n";
  if (r.position_used == PositionSource::reference) {
    o << "  positions: the admittance reference x_ref, not the encoder ("
      << (r.settings.position == PositionSource::automatic ? "auto, a controller's log; --position-source encoder for the encoder"
                                                            : "--position-source reference")
      << "), aligned by 1 sample in " << r.n_reference_shift1 << " trials, by 0 in " << r.n_reference_shift0;
    if (!r.reference_fallback_trials.empty()) {
      o << "; the encoder in " << r.reference_fallback_trials.size() << " without a finite reference (trial";
      for (const int t : r.reference_fallback_trials) o << " " << t;
      o << ")";
    }
    o << "\n";
  }
  if (r.psd.n_unperturbed > 0)
    o << "  PSD: unperturbed peak " << fmt(r.psd.peak_unperturbed_hz, 3) << " Hz; auto cut-off "
      << fmt(r.psd.cutoff_auto_hz, 3) << " Hz (ratio > " << r.settings.cutoff_auto_threshold_db
      << " dB); perturbed/unperturbed at 1 Hz " << fmt(r.psd.ratio_at_1hz_db, 1) << " dB\n";

  // Table 1: one row per method, every element labelled, "estimate [95 % interval]".
  bool any_session = false;
  for (int which = 0; which < 2; ++which) {
    const char* m = which == 0 ? "D" : "K";
    TextTable t({"method", std::string(m) + "11 [" + (which == 0 ? "N s/m" : "N/m") + "]",
                 std::string(m) + "12", std::string(m) + "21", std::string(m) + "22", "n", "identifiable"});
    for (const auto& s : r.summaries) {
      if (!s.group.is_session()) continue;
      any_session = true;
      const Mat2& v = which == 0 ? s.d_nspm : s.k_npm;
      const Mat2& lo = which == 0 ? s.d_lo : s.k_lo;
      const Mat2& hi = which == 0 ? s.d_hi : s.k_hi;
      std::vector<std::string> row{method_label(s.method)};
      for (int i = 0; i < 4; ++i) row.push_back(with_interval(v(i / 2, i % 2), lo(i / 2, i % 2), hi(i / 2, i % 2)));
      row.push_back(std::to_string(s.n_trials));
      row.push_back(s.identifiable ? "yes" : "NO");
      t.add(row);
    }
    if (!any_session) break;
    o << "\n  session " << (which == 0 ? "damping D [N s/m]" : "stiffness K [N/m]")
      << ", estimate [95 % interval] (Table 1):\n"
      << t.str();
  }
  for (const auto& s : r.summaries) {
    if (!s.group.is_session()) continue;
    o << "  " << s.method << ": " << s.kind << "; M_BSP at onset ~ [" << num(s.m_kg(0, 0)) << ", " << num(s.m_kg(0, 1))
      << "; " << num(s.m_kg(1, 0)) << ", " << num(s.m_kg(1, 1)) << "] kg";
    if (s.disturbance)
      o << "; person's own motion (" << (s.disturbance->box_jenkins ? "box-jenkins" : "armax") << "): motor noise "
        << num(s.disturbance->motor_noise_n) << " N std, tau " << num(s.disturbance->motor_tau_s * 1000) << " ms, position noise "
        << num(s.disturbance->meas_std_m * 1e6) << " um std";
    o << "\n";
    if (!s.identifiable) o << "    ** " << s.method << " NOT IDENTIFIABLE: " << s.flag << " **\n";
    if (const auto b = method_bias_note(s.method); !b.empty()) o << "    ** " << s.method << " " << b << " **\n";
  }

  // Ground truth (simulated logs): the intrinsic truth (per trial, the
  // person's own D, K) and the apparent one (intrinsic + feedback within the
  // window, what the paper calls involuntary); each labelled, errors vs each.
  if (r.truth.available || r.truth.apparent) {
    const auto& ap = r.truth.apparent;
    auto window = [](double t) {
      std::ostringstream w;
      w << "[0, " << t << "] s";
      return w.str();
    };
    o << "\n  ground truth (simulated log):\n";
    TextTable t({"truth", "D11 [N s/m]", "D12", "D21", "D22", "K11 [N/m]", "K12", "K21", "K22"});
    auto truth_row = [&](const std::string& label, const Mat2& d, const Mat2& k) {
      std::vector<std::string> row{label};
      for (int i = 0; i < 4; ++i) row.push_back(num(d(i / 2, i % 2)));
      for (int i = 0; i < 4; ++i) row.push_back(num(k(i / 2, i % 2)));
      t.add(row);
    };
    if (r.truth.available) truth_row("intrinsic", r.truth.d_nspm, r.truth.k_npm);
    if (ap) truth_row("apparent", ap->d_nspm, ap->k_npm);
    o << t.str();
    if (r.truth.available)
      o << "    intrinsic: the person's own D, K about the movement (" << r.truth.model << "), mean over "
        << r.truth.n_trials << " trials\n";
    if (ap) {
      o << "    apparent: intrinsic + reflex within the window " << window(ap->t_est_s)
        << ", the constant D, K that best fit the exact noise-free response (session-level)\n";
      if (std::abs(ap->t_est_s - r.settings.pipeline.t_est_s) > 1e-9)
        o << "    note: the apparent truth is for " << window(ap->t_est_s) << ", this estimate used T_est "
          << num(r.settings.pipeline.t_est_s) << " s\n";
    }
    auto errors = [&](const std::string& title, const Mat2& td, const Mat2& tk) {
      o << "  " << title << " [% of the true element]:\n";
      TextTable e({"method", "D11", "D12", "D21", "D22", "K11", "K12", "K21", "K22"});
      for (const auto& s : r.summaries) {
        if (!s.group.is_session()) continue;
        std::vector<std::string> er{method_label(s.method)};
        for (int i = 0; i < 4; ++i) {
          const double tv = td(i / 2, i % 2);
          er.push_back(fmt(100.0 * (s.d_nspm(i / 2, i % 2) - tv) / std::abs(tv), 1) + " %");
        }
        for (int i = 0; i < 4; ++i) {
          const double tv = tk(i / 2, i % 2);
          er.push_back(fmt(100.0 * (s.k_npm(i / 2, i % 2) - tv) / std::abs(tv), 1) + " %");
        }
        e.add(er);
      }
      o << e.str();
    };
    if (r.truth.available) errors("error vs intrinsic truth", r.truth.d_nspm, r.truth.k_npm);
    if (ap) errors("error vs apparent truth (intrinsic + reflex within the window)", ap->d_nspm, ap->k_npm);
  }

  // Per angle: the impedance along the push (directional.hpp); the per-angle
  // 2x2 fits are not identifiable and not printed (JSON/CSV keep them, flagged).
  {
    // "true": along the push, of the intrinsic truth; "apparent": of the apparent truth (when the log has it).
    const auto& ap = r.truth.apparent;
    std::vector<std::string> head{"angle [deg]", "n", "D_dir [N s/m]", "K_dir [N/m]", "D_dir true", "K_dir true"};
    if (ap) {
      head.push_back("D_dir apparent");
      head.push_back("K_dir apparent");
    }
    TextTable t(head);
    bool any = false;
    for (const auto& s : r.summaries) {
      if (!s.group.is_angle() || !s.directional || s.method != r.summaries.front().method) continue;
      const auto& d = *s.directional;
      std::vector<std::string> row{num(d.angle_deg), std::to_string(d.n_trials), with_interval(d.d_nspm, d.d_lo, d.d_hi),
                                   with_interval(d.k_npm, d.k_lo, d.k_hi),
                                   r.truth.available ? num(d.d_true) : std::string("n/a"),
                                   r.truth.available ? num(d.k_true) : std::string("n/a")};
      if (ap) {
        row.push_back(num(d.u.dot(ap->d_nspm * d.u)));
        row.push_back(num(d.u.dot(ap->k_npm * d.u)));
      }
      t.add(row);
      any = true;
    }
    if (any)
      o << "\n  per angle: impedance along the push u (uᵀDu, uᵀKu), mean [95 % interval] over trials; "
           "a single push direction cannot determine the 2x2 D and K:\n"
        << t.str();
  }

  if (!r.trials.empty()) {
    TextTable t({"method", "trial", "angle [deg]", "D11 [N s/m]", "D12", "D21", "D22", "K11 [N/m]", "K12", "K21", "K22",
                 "VAF", "flag"});
    for (const auto& tr : r.trials) {
      std::vector<std::string> row{tr.method, std::to_string(tr.trial), num(tr.angle_deg)};
      for (int i = 0; i < 4; ++i) row.push_back(num(tr.est.d_nspm(i / 2, i % 2)));
      for (int i = 0; i < 4; ++i) row.push_back(num(tr.est.k_npm(i / 2, i % 2)));
      row.push_back(fmt(tr.est.vaf, 2));
      row.push_back(tr.est.identifiable ? "" : "not identifiable");
      t.add(row);
    }
    o << "\n  per trial (one push direction each: 2x2 values not identifiable, shown for diagnosis):\n" << t.str();
  }
  for (const auto& i : r.issues) o << "  excluded: trial " << i.trial << ": " << i.reason << "\n";
  for (const auto& w : r.warnings) o << "  warning: " << w << "\n";
  return o.str();
}

}  // namespace manip::estimation
