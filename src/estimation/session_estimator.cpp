#include "manip/estimation/session_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "manip/common/channels.hpp"
#include "manip/common/errors.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/dsp/dsp.hpp"
#include "manip/estimation/tracking_input.hpp"

namespace manip::estimation {
namespace {

double to_deg(double rad) {
  double d = std::fmod(rad * 180.0 / std::numbers::pi, 360.0);
  if (d < 0) d += 360.0;
  return std::round(d * 1000.0) / 1000.0;
}

}  // namespace

SessionEstimator::SessionEstimator(EstimatorSettings s) : s_(std::move(s)) {
  for (const auto& m : s_.methods) {
    const Method* method = find_method(m);
    if (!method) throw std::invalid_argument("unknown method '" + m + "' (known: " + method_list() + ", all)");
    methods_.push_back(method);
    windows_ = windows_ | method->windows();
  }
}

void SessionEstimator::add_trial(const SessionInfo& info, TrialData&& t) {
  if (!have_info_) {
    info_ = info;
    have_info_ = true;
  }
  ++n_trials_;
  // The window rule costs ~1 ms: resolve it once per session (recorded in the report's settings).
  if (s_.pipeline.sg_window <= 0) s_.pipeline.sg_window = sg_window_for(s_.pipeline, info.sample_rate_hz);
  // PSD of the principal-axis jerk with one segment spanning the trial
  // (zero-padded to a common nfft so all trials share one frequency grid).
  // The same filter and values as principal_axis_jerk(), with the filter
  // designed once per session and the buffers reused.
  const int win = s_.pipeline.sg_window;
  if (t.size() >= static_cast<std::size_t>(win)) {
    if (!jerk_filter_) jerk_filter_ = std::make_unique<dsp::SavgolFilter>(win, s_.pipeline.sg_order, 3, 1.0 / info.sample_rate_hz);
    const std::size_t n = t.size();
    jerk_.resize(n);
    for (std::size_t i = 0; i < n; ++i) jerk_[i] = t.x_m[i](1);
    jerk_out_.resize(n);
    jerk_filter_->apply(jerk_, jerk_out_);
    const std::vector<double>& j = jerk_out_;
    dsp::WelchOptions wo;
    wo.nfft = s_.psd_nfft;
    wo.nperseg = static_cast<int>(std::min<std::size_t>(n, static_cast<std::size_t>(s_.psd_nfft)));
    wo.noverlap = wo.nperseg / 2;
    dsp::welch(j, info.sample_rate_hz, wo, psd_);
    if (f_.empty()) {
      f_ = psd_.f_hz;
      psd_unpert_.assign(f_.size(), 0.0);
      psd_pert_.assign(f_.size(), 0.0);
    }
    auto& acc = t.perturbed ? psd_pert_ : psd_unpert_;
    for (std::size_t i = 0; i < acc.size() && i < psd_.pxx.size(); ++i) acc[i] += psd_.pxx[i];
    (t.perturbed ? n_pert_psd_ : n_unpert_) += 1;
  }
  if (!t.perturbed) return;
  ++n_perturbed_;
  if (s_.cutoff_auto) {
    perturbed_.push_back(std::move(t));  // the cut-off is known only after the last PSD
  } else {
    // The x2 jerk of this trial is still in jerk_out_ if the PSD was computed.
    const bool have_jerk = t.size() >= static_cast<std::size_t>(win) && jerk_out_.size() == t.size();
    prepared_.push_back(prepare(t, s_.pipeline, have_jerk ? std::span<const double>(jerk_out_) : std::span<const double>{}));
  }
}

SessionEstimator::Prepared SessionEstimator::prepare(const TrialData& trial, const PipelineSettings& pipe,
                                                     std::span<const double> jerk_x2) const {
  Prepared p;
  p.trial = trial.trial;
  try {
    // Position "reference" (and "auto" on a controller's log): every method
    // sees the aligned admittance reference as x (trial_data.hpp); the x2
    // jerk computed for the PSD was the encoder's, so it is recomputed.
    // "tracked": the encoder stays x, and the reference gives the tracking
    // input (tracking_input.hpp).
    std::optional<std::vector<Vec2>> x_ref;
    const int shift = reference_shift_for(info_.source);
    const PositionSource pos = resolved_position(s_.position, info_.source);
    if (pos == PositionSource::reference || pos == PositionSource::tracked) {
      try {
        x_ref = aligned_reference(trial, shift);
      } catch (const std::invalid_argument&) {
        // "auto" keeps the trial on the encoder (the paper's position); an
        // explicit "reference" or "tracked" excludes it with the reason.
        if (s_.position != PositionSource::automatic) throw;
        p.reference_fallback = true;
      }
    }
    if (x_ref) p.reference_shift = shift;
    const bool tracked = x_ref && pos == PositionSource::tracked;
    TrialData on_ref;
    if (x_ref && !tracked) {
      on_ref = trial;
      on_ref.x_m = std::move(*x_ref);
      jerk_x2 = {};
    }
    const TrialData& t = x_ref && !tracked ? on_ref : trial;
    const TwoLinkArm arm(info_.anthropometrics);
    const Vec2 x_on = t.x_m.at(static_cast<std::size_t>(t.onset_index));
    const auto m_bsp = arm.endpoint_inertia_at(x_on);
    if (!m_bsp)
      throw std::invalid_argument("trial " + std::to_string(t.trial) + ": onset position (" + std::to_string(x_on.x()) +
                                  ", " + std::to_string(x_on.y()) + ") m out of the arm's reach");
    p.vw = isolate_variational(info_, t, pipe, jerk_x2);
    if (needs(windows_, DataWindow::output_error)) p.ow = make_oe_window(info_, t, *m_bsp, s_.oe);
    if (needs(windows_, DataWindow::prediction_error)) p.pw = make_pem_window(info_, t, *m_bsp, s_.pem);
    if (tracked) {
      OeWindow* const w[] = {&p.ow, &p.pw};
      add_tracking_input(info_, trial, *x_ref, pipe, p.vw, w);
    }
    p.m_bsp = *m_bsp;
    if (t.has_truth) {
      p.has_truth = true;
      p.truth_d = t.truth_d_nspm;
      p.truth_k = t.truth_k_npm;
      p.truth_m = t.truth_m_kg;
      p.truth_model = t.truth_model;
    }
  } catch (const std::exception& e) {
    p.error = e.what();
  }
  return p;
}

Report SessionEstimator::finish(std::vector<TrialIssue> issues, std::vector<std::string> warnings) {
  Report rep;
  rep.info = info_;
  rep.truth.apparent = apparent_;
  rep.settings = s_;
  rep.position_used = resolved_position(s_.position, info_.source);
  rep.issues = std::move(issues);
  rep.warnings = std::move(warnings);
  rep.n_trials = n_trials_;
  rep.n_perturbed = n_perturbed_;
  if (!have_info_) return rep;
  rep.sg_window = sg_window_for(s_.pipeline, info_.sample_rate_hz);

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

  // Per-trial preparation: M_BSP at onset (eq. 16), isolated Δ signals, OE
  // windows; done in add_trial already unless the cut-off was chosen above.
  if (s_.cutoff_auto) {
    for (const auto& t : perturbed_) prepared_.push_back(prepare(t, pipe, {}));
    perturbed_.clear();
  }
  std::vector<VariationalWindow> vw;
  std::vector<Mat2> mb;
  std::vector<OeWindow> ow, pw;
  std::vector<int> vw_trial;
  TruthSummary& truth = rep.truth;
  for (auto& p : prepared_) {
    if (p.error) {
      rep.issues.push_back({p.trial, *p.error});
      continue;
    }
    vw.push_back(std::move(p.vw));
    mb.push_back(p.m_bsp);
    ow.push_back(std::move(p.ow));
    pw.push_back(std::move(p.pw));
    vw_trial.push_back(p.trial);
    if (p.reference_shift == 0) ++rep.n_reference_shift0;
    if (p.reference_shift == 1) ++rep.n_reference_shift1;
    if (p.reference_fallback) rep.reference_fallback_trials.push_back(p.trial);
    if (p.has_truth) {
      truth.available = true;
      ++truth.n_trials;
      truth.d_nspm += p.truth_d;
      truth.k_npm += p.truth_k;
      truth.m_kg += p.truth_m;
      truth.model = p.truth_model;
    }
  }
  prepared_.clear();
  if (truth.n_trials > 0) {
    truth.d_nspm /= truth.n_trials;
    truth.k_npm /= truth.n_trials;
    truth.m_kg /= truth.n_trials;
  }
  rep.n_used = static_cast<int>(vw.size());
  std::set<double> angles;
  for (const auto& w : vw) angles.insert(to_deg(w.angle_rad));

  const SessionWindows data{&info_, &s_, vw, mb, needs(windows_, DataWindow::output_error) ? std::span<const OeWindow>(ow) : std::span<const OeWindow>{},
                            needs(windows_, DataWindow::prediction_error) ? std::span<const OeWindow>(pw) : std::span<const OeWindow>{}};
  for (const Method* method : methods_) {
    if (vw.empty()) break;
    const std::string name = method->name();
    if (method->per_trial()) {
      std::vector<TrialResult> per;
      for (std::size_t i = 0; i < vw.size(); ++i) {
        TrialResult r;
        r.trial = vw[i].trial;
        r.angle_deg = to_deg(vw[i].angle_rad);
        r.method = name;
        try {
          r.est = method->fit(data, {std::span(&i, 1), nullptr});
        } catch (const std::exception& e) {
          rep.issues.push_back({vw[i].trial, name + ": " + e.what()});
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
      rep.summaries.push_back(summarise_trials(name, SummaryGroup::session(), all));
      for (double a : angles) {
        std::vector<const TrialResult*> sub;
        for (const auto& r : per)
          if (r.angle_deg == a) sub.push_back(&r);
        rep.summaries.push_back(summarise_trials(name, SummaryGroup::angle(a), sub));
      }
      rep.trials.insert(rep.trials.end(), per.begin(), per.end());
    } else {
      std::optional<ImpedanceEstimate> session_fit;
      std::vector<std::size_t> idx(vw.size());
      for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
      try {
        session_fit = method->fit(data, {idx, nullptr});
        rep.summaries.push_back(summarise_pooled(name, SummaryGroup::session(), *session_fit));
      } catch (const std::exception& e) {
        rep.warnings.push_back(name + ": session fit failed: " + e.what());
      }
      for (double a : angles) {
        std::vector<std::size_t> sub;
        for (std::size_t i = 0; i < vw.size(); ++i)
          if (to_deg(vw[i].angle_rad) == a) sub.push_back(i);
        try {
          rep.summaries.push_back(
              summarise_pooled(name, SummaryGroup::angle(a), method->fit(data, {sub, session_fit ? &*session_fit : nullptr})));
        } catch (const std::exception& e) {
          rep.warnings.push_back(name + ": angle " + std::to_string(a) + " fit failed: " + e.what());
        }
      }
    }
  }
  // Per angle: the impedance along the push (the one honest per-angle
  // result) and the 2x2 fits flagged; the session's pooled 2x2 is untouched.
  // The 1-D fit does not depend on the method: computed once per angle.
  std::map<double, DirectionalEstimate> dir;
  for (double a : angles) {
    std::vector<VariationalWindow> sub;
    std::vector<Mat2> sub_m;
    for (std::size_t i = 0; i < vw.size(); ++i)
      if (to_deg(vw[i].angle_rad) == a) {
        sub.push_back(vw[i]);
        sub_m.push_back(mb[i]);
      }
    try {
      DirectionalEstimate d = fit_directional(sub, sub_m, s_.ls.force, a);
      if (truth.available) {
        d.d_true = d.u.dot(truth.d_nspm * d.u);
        d.k_true = d.u.dot(truth.k_npm * d.u);
      }
      dir.emplace(a, std::move(d));
    } catch (const std::exception& e) {
      rep.warnings.push_back("angle " + std::to_string(a) + ": directional fit failed: " + e.what());
    }
  }
  static const std::string kNotIdentifiable =
      "2x2 D, K not identifiable from one push direction; read D_dir/K_dir (impedance along the push)";
  for (auto& sm : rep.summaries) {
    if (!sm.group.is_angle()) continue;
    if (auto it = dir.find(sm.group.angle_deg); it != dir.end()) sm.directional = it->second;
    sm.identifiable = false;
    sm.flag = sm.flag.empty() ? kNotIdentifiable : kNotIdentifiable + "; " + sm.flag;
  }
  if (s_.keep_windows) rep.windows = std::move(vw);
  return rep;
}

namespace {

// Single-producer single-consumer queue of trials, bounded so that a reader
// faster than the worker waits instead of buffering the session.
class TrialQueue {
 public:
  explicit TrialQueue(std::size_t capacity) : cap_(capacity) {}
  // False if the consumer has stopped (the item is dropped).
  bool push(TrialData&& t) {
    std::unique_lock lk(m_);
    not_full_.wait(lk, [&] { return q_.size() < cap_ || stopped_; });
    if (stopped_) return false;
    q_.push_back(std::move(t));
    not_empty_.notify_one();
    return true;
  }
  // Empty optional once closed and drained.
  std::optional<TrialData> pop() {
    std::unique_lock lk(m_);
    not_empty_.wait(lk, [&] { return !q_.empty() || closed_; });
    if (q_.empty()) return std::nullopt;
    TrialData t = std::move(q_.front());
    q_.pop_front();
    not_full_.notify_one();
    return t;
  }
  void close() {  // producer: no more items
    std::lock_guard lk(m_);
    closed_ = true;
    not_empty_.notify_all();
  }
  void stop() {  // consumer: failed, take no more items
    std::lock_guard lk(m_);
    stopped_ = true;
    q_.clear();
    not_full_.notify_all();
  }

 private:
  std::mutex m_;
  std::condition_variable not_full_, not_empty_;
  std::deque<TrialData> q_;
  std::size_t cap_;
  bool closed_{false}, stopped_{false};
};

}  // namespace

namespace {

struct LiveRate {
  std::uint64_t n{0};
  double rate_hz{0};
};

// Count and mean rate of MANIP_STATE_LIVE events (by their LCM timestamps).
LiveRate live_state_rate(const std::string& path) {
  LiveRate r;
  try {
    logging::EventLogReader rd(path);
    logging::RawEvent ev;
    std::int64_t t0 = 0, t1 = 0;
    while (rd.next(ev)) {
      if (ev.channel != manip::channels::kStateLive) continue;
      if (r.n == 0) t0 = ev.utime;
      t1 = ev.utime;
      ++r.n;
    }
    if (r.n > 1 && t1 > t0) r.rate_hz = static_cast<double>(r.n - 1) / (static_cast<double>(t1 - t0) * 1e-6);
  } catch (const std::exception&) {
    // Unreadable here means it was already reported by read_log's warnings.
  }
  return r;
}

}  // namespace

Report estimate_log(const std::string& path, const EstimatorSettings& s) {
  SessionEstimator est(s);
  // A trial is ~0.5-2 MB; four in flight keep both threads busy.
  TrialQueue queue(4);
  // Written by the reader once, before the first push (the session message
  // comes first and is never replaced); the queue's mutex orders it before
  // the worker's first read.
  SessionInfo info;
  bool have_info = false;
  std::exception_ptr worker_error;
  std::thread worker([&] {
    try {
      while (auto t = queue.pop()) est.add_trial(info, std::move(*t));
    } catch (...) {
      worker_error = std::current_exception();
      queue.stop();
    }
  });
  TrialAssembler asmb([&](const SessionInfo& i, TrialData&& t) {
    if (!have_info) {
      info = i;
      have_info = true;
    }
    queue.push(std::move(t));  // false only after a worker error, rethrown below
  });
  // Unperturbed trials only feed the PSD of x2: skip copying their other signals.
  asmb.set_keep_unperturbed_signals(false);
  try {
    logging::read_log(path, asmb);
    asmb.finish();
  } catch (const std::exception& e) {
    queue.close();
    worker.join();
    // Every reason a log cannot be read is "input unusable"; name the file once.
    const std::string what = e.what();
    throw manip::InputError(what.rfind(path, 0) == 0 ? what : path + ": " + what);
  }
  queue.close();
  worker.join();
  if (worker_error) std::rethrow_exception(worker_error);
  if (asmb.apparent_truth()) est.set_apparent_truth(*asmb.apparent_truth());
  if (asmb.states_seen() == 0) {
    // A recording of the live bus (lcm-logger) holds the decimated
    // MANIP_STATE_LIVE only: say so instead of "no usable trial" (issue 13).
    const auto live = live_state_rate(path);
    if (live.n > 0) {
      std::ostringstream m;
      m << path << ": no " << manip::channels::kState << " (4 kHz) channel: this looks like a live-bus recording ("
        << manip::channels::kStateLive << " at " << std::llround(live.rate_hz) << " Hz, " << live.n
        << " messages); record with manip_rt --out";
      throw manip::InputError(m.str());
    }
  }
  if (!asmb.has_session()) throw manip::InputError(path + ": no session message (MANIP_SESSION) in the log");
  Report rep = est.finish(asmb.issues(), asmb.warnings());
  // No trial reached the estimator (a log shorter than one trial): the session
  // is still the log's, not empty fields (issue 13).
  if (!have_info) rep.info = asmb.session();
  return rep;
}

}  // namespace manip::estimation
