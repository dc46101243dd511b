#pragma once
// Everything estimate_impedance does to one session: trials in, report out.
// Perturbed trials are kept (they are needed after the PSDs when the cut-off
// is chosen automatically); unperturbed trials only feed the PSD and are
// dropped at once, so memory stays bounded however long the session.
#include <map>
#include <string>
#include <vector>

#include "manip/estimation/impedance.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

// Method names (docs/estimator.md):
//   paper         per-trial equation error on high-pass-isolated signals (§3, eq. 30-32); mean (std) over trials
//   paper-pooled  the same signals, one fit over all perturbed trials; estimate (SE, 95% CI)
//   oe            default: pooled causal output error with per-trial polynomial; jackknife SE, 95% CI
//   oe-trial      the output-error fit per trial; mean (std) over trials
std::vector<std::string> all_methods();
std::string default_method();

struct EstimatorSettings {
  PipelineSettings pipeline{};
  bool cutoff_auto{false};
  double cutoff_auto_threshold_db{3.0};
  int psd_nfft{65536};
  LsOptions ls{};
  OeSettings oe{};
  std::vector<std::string> methods{default_method()};
  bool keep_windows{false};  // keep variational windows for --export-signals / --plots
};

struct TrialResult {
  int trial{-1};
  double angle_deg{0};
  std::string method;
  ImpedanceEstimate est;
  // Validation against a simulator's twin (NaN for lab logs): NRMSE of Δx at T_est per axis.
  Vec2 nrmse_dx{Vec2::Constant(std::numeric_limits<double>::quiet_NaN())};
};

struct Summary {
  std::string method;
  std::string group;        // "session" or "angle 30" etc.
  std::string kind;         // "mean (std) over trials" or "pooled fit"
  int n_trials{0};
  Mat2 d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()};
  Mat2 d_spread{Mat2::Zero()}, k_spread{Mat2::Zero()};  // std over trials, or SE of the pooled fit
  Mat2 d_lo{Mat2::Zero()}, d_hi{Mat2::Zero()}, k_lo{Mat2::Zero()}, k_hi{Mat2::Zero()};  // 95% interval
  Mat2 m_kg{Mat2::Zero()};
  bool identifiable{true};
  std::string flag;
  int n_flagged_trials{0};
};

struct PsdReport {
  std::vector<double> f_hz, p_unperturbed, p_perturbed;
  int n_unperturbed{0}, n_perturbed{0};
  double peak_unperturbed_hz{0};
  double cutoff_auto_hz{std::numeric_limits<double>::quiet_NaN()};
  double ratio_at_1hz_db{std::numeric_limits<double>::quiet_NaN()};
};

struct TruthSummary {
  bool available{false};
  int n_trials{0};
  Mat2 d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()}, m_kg{Mat2::Zero()};
  std::string model;
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
};

class SessionEstimator {
 public:
  explicit SessionEstimator(EstimatorSettings s);
  void add_trial(const SessionInfo& info, TrialData&& t);
  // Runs the methods; issues/warnings gathered while reading are appended.
  Report finish(std::vector<TrialIssue> issues, std::vector<std::string> warnings);

 private:
  EstimatorSettings s_;
  SessionInfo info_;
  bool have_info_{false};
  std::vector<TrialData> perturbed_;
  std::vector<double> psd_unpert_, psd_pert_, f_;
  int n_unpert_{0}, n_pert_psd_{0}, n_trials_{0};
  std::vector<TrialIssue> local_issues_;
};

// Convenience: read a log file and estimate. Throws std::runtime_error for
// unusable files (message names the file and the reason).
Report estimate_log(const std::string& path, const EstimatorSettings& s);

}  // namespace manip::estimation
