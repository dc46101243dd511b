#pragma once
// Everything estimate_impedance does to one session: trials in, report out.
// Unperturbed trials only feed the PSD and are dropped at once; perturbed
// trials are reduced to their isolated windows at once, or, when the cut-off
// is chosen automatically (known only after the last PSD), kept whole until
// finish(). Memory stays bounded however long the session.
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "manip/dsp/savgol.hpp"
#include "manip/dsp/welch.hpp"

#include "manip/estimation/impedance.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/pem.hpp"
#include "manip/estimation/settings.hpp"
#include "manip/estimation/summary.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

struct PsdReport {
  std::vector<double> f_hz, p_unperturbed, p_perturbed;
  int n_unperturbed{0}, n_perturbed{0};
  double peak_unperturbed_hz{0};
  double cutoff_auto_hz{std::numeric_limits<double>::quiet_NaN()};
  double ratio_at_1hz_db{std::numeric_limits<double>::quiet_NaN()};
};

// Ground truth of a simulated log. `available`, d_nspm, k_npm, m_kg, model:
// the intrinsic truth (per-trial MANIP_TRUTH_IMPEDANCE, the person's own D, K
// about the movement) averaged over the used trials. `apparent`: the session's
// apparent truth (intrinsic + feedback within the window, trial_data.hpp), if
// the log carries one; it can be present without the intrinsic one.
struct TruthSummary {
  bool available{false};
  int n_trials{0};
  Mat2 d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()}, m_kg{Mat2::Zero()};
  std::string model;
  std::optional<ApparentTruth> apparent;
};

struct Report {
  SessionInfo info;
  EstimatorSettings settings;
  double cutoff_used_hz{1.0};
  int sg_window{0};
  int n_trials{0}, n_perturbed{0}, n_used{0};
  std::vector<TrialResult> trials;
  std::vector<Summary> summaries;   // per method: session first, then per angle
  PsdReport psd;
  TruthSummary truth;
  std::vector<TrialIssue> issues;
  std::vector<std::string> warnings;
  std::vector<VariationalWindow> windows;  // if keep_windows
  // The position the session's trials took (EstimatorSettings::position
  // resolved for info.source: resolved_position). On the reference: used
  // trials whose logged x_ref was aligned by 0 and by 1 sample
  // (aligned_reference), and, under "auto" only, the trials without a finite
  // reference that took the encoder instead (an explicit "reference" excludes
  // them, naming each).
  PositionSource position_used{PositionSource::encoder};
  int n_reference_shift0{0}, n_reference_shift1{0};
  std::vector<int> reference_fallback_trials;
};

class SessionEstimator {
 public:
  explicit SessionEstimator(EstimatorSettings s);
  // Trials must come in log order (the PSD sums and the per-trial lists are
  // accumulated in call order). With a fixed cut-off (no cutoff_auto) a
  // perturbed trial is isolated here at once and only its windows are kept;
  // with cutoff_auto it is kept whole until finish().
  void add_trial(const SessionInfo& info, TrialData&& t);
  // The session's apparent truth (TrialAssembler::apparent_truth()), carried
  // into Report::truth.apparent. Any time before finish().
  void set_apparent_truth(const ApparentTruth& a) { apparent_ = a; }
  // Runs the methods; issues/warnings gathered while reading are appended.
  Report finish(std::vector<TrialIssue> issues, std::vector<std::string> warnings);

 private:
  // Per perturbed trial: M_BSP at onset, isolated signals, the windows the
  // selected methods need (or the reason it could not be used), in trial order.
  struct Prepared {
    int trial{-1};
    std::optional<std::string> error;
    VariationalWindow vw;
    Mat2 m_bsp{Mat2::Zero()};
    OeWindow ow;  // output-error window, if a selected method needs it
    OeWindow pw;  // prediction-error window (its own pre-onset span), if needed
    bool has_truth{false};
    Mat2 truth_d{Mat2::Zero()}, truth_k{Mat2::Zero()}, truth_m{Mat2::Zero()};
    std::string truth_model;
    int reference_shift{-1};  // position "reference": samples the logged x_ref was shifted by (0, 1)
    bool reference_fallback{false};  // "auto": no finite reference in this trial, the encoder taken
  };
  // jerk_x2: the trial's x2 jerk if already computed (for the PSD), else empty.
  Prepared prepare(const TrialData& t, const PipelineSettings& pipe, std::span<const double> jerk_x2) const;

  EstimatorSettings s_;
  std::vector<const Method*> methods_;  // s_.methods resolved in the registry
  DataWindow windows_{DataWindow::variational};  // union of their needs
  SessionInfo info_;
  bool have_info_{false};
  std::optional<ApparentTruth> apparent_;
  std::vector<TrialData> perturbed_;  // cutoff_auto only
  std::vector<Prepared> prepared_;    // fixed cut-off
  std::vector<double> psd_unpert_, psd_pert_, f_;
  int n_unpert_{0}, n_pert_psd_{0}, n_trials_{0}, n_perturbed_{0};
  // Reused per trial: the jerk filter (designed once per session), the jerk and the PSD.
  std::unique_ptr<dsp::SavgolFilter> jerk_filter_;
  std::vector<double> jerk_, jerk_out_;
  dsp::Psd psd_;
};

// Convenience: read a log file and estimate. Throws manip::InputError for
// unusable files (message names the file and the reason, e.g. an invalid
// session message names the field). The log is decoded
// on the calling thread while a second thread runs SessionEstimator::add_trial
// on each trial as it completes (a bounded queue of a few trials between them
// keeps memory bounded); the result is identical to a sequential run, since
// one worker takes the trials in log order.
Report estimate_log(const std::string& path, const EstimatorSettings& s);

}  // namespace manip::estimation
