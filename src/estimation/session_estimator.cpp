#include "manip/estimation/session_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <stdexcept>

#include "manip/dsp/dsp.hpp"

namespace manip::estimation {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double to_deg(double rad) {
  double d = std::fmod(rad * 180.0 / std::numbers::pi, 360.0);
  if (d < 0) d += 360.0;
  return std::round(d * 1000.0) / 1000.0;
}

bool per_trial_method(const std::string& m) { return m == "paper" || m == "oe-trial"; }

// Mean (std) over per-trial estimates, laid out like Table 1.
Summary summarise_trials(const std::string& method, const std::string& group, const std::vector<const TrialResult*>& rs) {
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
  const double t = rs.size() > 1 ? t_quantile_975(static_cast<int>(rs.size()) - 1) / std::sqrt(n) : kNaN;
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

Summary summarise_pooled(const std::string& method, const std::string& group, const ImpedanceEstimate& e) {
  Summary s;
  s.method = method;
  s.group = group;
  s.kind = "pooled fit (" + e.se_kind + ")";
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
  return s;
}

}  // namespace

std::vector<std::string> all_methods() { return {"paper", "paper-pooled", "oe", "oe-trial"}; }
std::string default_method() { return "oe"; }

SessionEstimator::SessionEstimator(EstimatorSettings s) : s_(std::move(s)) {
  for (const auto& m : s_.methods) {
    const auto all = all_methods();
    if (std::find(all.begin(), all.end(), m) == all.end())
      throw std::invalid_argument("unknown method '" + m + "' (known: paper, paper-pooled, oe, oe-trial, all)");
  }
}

void SessionEstimator::add_trial(const SessionInfo& info, TrialData&& t) {
  if (!have_info_) {
    info_ = info;
    have_info_ = true;
  }
  ++n_trials_;
  // The window rule costs ~1 ms: resolve it once per session (recorded in the report's settings).
  if (s_.pipeline.sg_window <= 0) s_.pipeline.sg_window = sg_window_for(s_.pipeline, info.fs_hz);
  // PSD of the principal-axis jerk with one segment spanning the trial
  // (zero-padded to a common nfft so all trials share one frequency grid).
  const auto j = principal_axis_jerk(info, t, s_.pipeline);
  if (!j.empty()) {
    dsp::WelchOptions wo;
    wo.nfft = s_.psd_nfft;
    wo.nperseg = static_cast<int>(std::min<std::size_t>(j.size(), static_cast<std::size_t>(s_.psd_nfft)));
    wo.noverlap = wo.nperseg / 2;
    const auto psd = dsp::welch(j, info.fs_hz, wo);
    if (f_.empty()) {
      f_ = psd.f_hz;
      psd_unpert_.assign(f_.size(), 0.0);
      psd_pert_.assign(f_.size(), 0.0);
    }
    auto& acc = t.perturbed ? psd_pert_ : psd_unpert_;
    for (std::size_t i = 0; i < acc.size() && i < psd.pxx.size(); ++i) acc[i] += psd.pxx[i];
    (t.perturbed ? n_pert_psd_ : n_unpert_) += 1;
  }
  if (t.perturbed) perturbed_.push_back(std::move(t));
}

Report SessionEstimator::finish(std::vector<TrialIssue> issues, std::vector<std::string> warnings) {
  Report rep;
  rep.info = info_;
  rep.settings = s_;
  rep.issues = std::move(issues);
  rep.warnings = std::move(warnings);
  rep.n_trials = n_trials_;
  rep.n_perturbed = static_cast<int>(perturbed_.size());
  if (!have_info_) return rep;
  rep.sg_window = sg_window_for(s_.pipeline, info_.fs_hz);

  // PSDs (Fig. 3) and the automatic cut-off (§4.3).
  auto& psd = rep.psd;
  psd.f_hz = f_;
  psd.n_unperturbed = n_unpert_;
  psd.n_perturbed = n_pert_psd_;
  psd.p_unperturbed = psd_unpert_;
  psd.p_perturbed = psd_pert_;
  for (auto& v : psd.p_unperturbed) v /= std::max(1, n_unpert_);
  for (auto& v : psd.p_perturbed) v /= std::max(1, n_pert_psd_);
  if (n_unpert_ > 0 && !f_.empty()) {
    const auto peak = std::max_element(psd.p_unperturbed.begin() + 1, psd.p_unperturbed.end());
    const auto ip = static_cast<std::size_t>(peak - psd.p_unperturbed.begin());
    psd.peak_unperturbed_hz = f_[ip];
    if (n_pert_psd_ > 0) {
      for (std::size_t i = ip; i < f_.size(); ++i) {
        const double ratio_db = 10.0 * std::log10(psd.p_perturbed[i] / psd.p_unperturbed[i]);
        if (ratio_db > s_.cutoff_auto_threshold_db) {
          psd.cutoff_auto_hz = f_[i];
          break;
        }
      }
      const auto i1 = static_cast<std::size_t>(std::lower_bound(f_.begin(), f_.end(), 1.0) - f_.begin());
      if (i1 < f_.size()) psd.ratio_at_1hz_db = 10.0 * std::log10(psd.p_perturbed[i1] / psd.p_unperturbed[i1]);
    }
  }
  PipelineSettings pipe = s_.pipeline;
  if (s_.cutoff_auto) {
    if (std::isfinite(psd.cutoff_auto_hz)) {
      pipe.hp_cutoff_hz = psd.cutoff_auto_hz;
    } else {
      rep.warnings.push_back("--cutoff auto: no frequency where perturbed/unperturbed PSD ratio exceeds " +
                             std::to_string(s_.cutoff_auto_threshold_db) + " dB (needs unperturbed and perturbed trials); using " +
                             std::to_string(pipe.hp_cutoff_hz) + " Hz");
    }
  }
  rep.cutoff_used_hz = pipe.hp_cutoff_hz;

  // Per-trial preparation: M_BSP at onset (eq. 16), isolated Δ signals, OE windows.
  const TwoLinkArm arm(info_.anthropometrics);
  std::vector<VariationalWindow> vw;
  std::vector<Mat2> mb;
  std::vector<OeWindow> ow;
  std::vector<int> vw_trial;
  TruthSummary& truth = rep.truth;
  for (const auto& t : perturbed_) {
    try {
      const Vec2 x_on = t.x_m.at(static_cast<std::size_t>(t.onset_index));
      const auto m_bsp = arm.endpoint_inertia_at(x_on);
      if (!m_bsp)
        throw std::invalid_argument("trial " + std::to_string(t.trial) + ": onset position (" + std::to_string(x_on.x()) +
                                    ", " + std::to_string(x_on.y()) + ") m out of the arm's reach");
      auto w = isolate_variational(info_, t, pipe);
      auto o = make_oe_window(info_, t, *m_bsp, s_.oe);
      vw.push_back(std::move(w));
      mb.push_back(*m_bsp);
      ow.push_back(std::move(o));
      vw_trial.push_back(t.trial);
      if (t.has_truth) {
        truth.available = true;
        ++truth.n_trials;
        truth.d_nspm += t.truth_d_nspm;
        truth.k_npm += t.truth_k_npm;
        truth.m_kg += t.truth_m_kg;
        truth.model = t.truth_model;
      }
    } catch (const std::exception& e) {
      rep.issues.push_back({t.trial, e.what()});
    }
  }
  if (truth.n_trials > 0) {
    truth.d_nspm /= truth.n_trials;
    truth.k_npm /= truth.n_trials;
    truth.m_kg /= truth.n_trials;
  }
  rep.n_used = static_cast<int>(vw.size());
  std::set<double> angles;
  for (const auto& w : vw) angles.insert(to_deg(w.angle_rad));

  for (const auto& method : s_.methods) {
    if (vw.empty()) break;
    std::vector<TrialResult> per;
    if (per_trial_method(method)) {
      for (std::size_t i = 0; i < vw.size(); ++i) {
        TrialResult r;
        r.trial = vw[i].trial;
        r.angle_deg = to_deg(vw[i].angle_rad);
        r.method = method;
        try {
          if (method == "paper") {
            r.est = fit_equation_error(std::span(&vw[i], 1), std::span(&mb[i], 1), s_.ls);
          } else {
            OeSettings o = s_.oe;
            o.jackknife = false;
            r.est = fit_output_error(std::span(&ow[i], 1), o);
          }
        } catch (const std::exception& e) {
          rep.issues.push_back({vw[i].trial, method + ": " + e.what()});
          continue;
        }
        if (!vw[i].dx_true.empty()) {
          Vec2 peak = Vec2::Zero(), se = Vec2::Zero();
          for (std::size_t k = 0; k < vw[i].size(); ++k) {
            peak = peak.cwiseMax(vw[i].dx_true[k].cwiseAbs());
            se += (vw[i].dx[k] - vw[i].dx_true[k]).cwiseAbs2();
          }
          r.nrmse_dx = (se / static_cast<double>(vw[i].size())).cwiseSqrt().cwiseQuotient(peak);
        }
        per.push_back(r);
      }
      std::vector<const TrialResult*> all;
      for (const auto& r : per) all.push_back(&r);
      rep.summaries.push_back(summarise_trials(method, "session", all));
      for (double a : angles) {
        std::vector<const TrialResult*> sub;
        for (const auto& r : per)
          if (r.angle_deg == a) sub.push_back(&r);
        rep.summaries.push_back(summarise_trials(method, "angle " + std::to_string(static_cast<int>(std::lround(a))), sub));
      }
      rep.trials.insert(rep.trials.end(), per.begin(), per.end());
    } else {
      auto pooled = [&](const std::vector<std::size_t>& idx, bool jack) {
        if (method == "paper-pooled") {
          std::vector<VariationalWindow> w;
          std::vector<Mat2> m;
          for (auto i : idx) {
            w.push_back(vw[i]);
            m.push_back(mb[i]);
          }
          return fit_equation_error(w, m, s_.ls);
        }
        std::vector<OeWindow> w;
        for (auto i : idx) w.push_back(ow[i]);
        OeSettings o = s_.oe;
        o.jackknife = jack && s_.oe.jackknife;
        return fit_output_error(w, o);
      };
      std::vector<std::size_t> idx(vw.size());
      for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
      try {
        rep.summaries.push_back(summarise_pooled(method, "session", pooled(idx, true)));
      } catch (const std::exception& e) {
        rep.warnings.push_back(method + ": session fit failed: " + e.what());
      }
      for (double a : angles) {
        std::vector<std::size_t> sub;
        for (std::size_t i = 0; i < vw.size(); ++i)
          if (to_deg(vw[i].angle_rad) == a) sub.push_back(i);
        try {
          rep.summaries.push_back(
              summarise_pooled(method, "angle " + std::to_string(static_cast<int>(std::lround(a))), pooled(sub, true)));
        } catch (const std::exception& e) {
          rep.warnings.push_back(method + ": angle " + std::to_string(a) + " fit failed: " + e.what());
        }
      }
    }
  }
  if (s_.keep_windows) rep.windows = std::move(vw);
  return rep;
}

Report estimate_log(const std::string& path, const EstimatorSettings& s) {
  SessionEstimator est(s);
  TrialAssembler asmb([&](const SessionInfo& info, TrialData&& t) { est.add_trial(info, std::move(t)); });
  logging::read_log(path, asmb);
  asmb.finish();
  if (!asmb.has_session()) throw std::runtime_error(path + ": no session message (MANIP_SESSION) in the log");
  return est.finish(asmb.issues(), asmb.warnings());
}

}  // namespace manip::estimation
