#pragma once
// The diagnosis engine: baseline fit, misfit signatures, mechanism search by
// cross-validation over contiguous blocks with a guard gap, greedy extension,
// and the measured gain with block-bootstrap intervals (docs/diagnosis.md).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "manip/diagnosis/dataset.hpp"
#include "manip/diagnosis/mechanisms.hpp"
#include "manip/diagnosis/stats.hpp"

namespace manip::diagnosis {

struct EngineOptions {
  int folds = 10;            // K-fold cross-validation over contiguous time blocks (or groups of segments)
  int blocks_per_fold = 3;   // bootstrap resamples these blocks (K * blocks_per_fold in all)
  double guard_s = 0.3;      // gap between folds: > reflex delay + filter memory, so test and training samples do not share a regressor's window
  double min_fold_s = 2.0;   // shortest usable fold
  double alpha = 0.05;       // family-wise level per greedy round (Holm over the candidates)
  int bootstrap = 200;       // block-bootstrap replicates
  std::uint64_t seed = 20261126;
  std::function<void(const std::string&)> progress;  // one line per step (stderr in the app)
  // Accept a significant candidate only if its full-data parameters lie within
  // their plausible ranges (a mechanism must keep its physical meaning; a
  // flexible one with absurd gains is fitting some other model error).
  // A shape parameter on the edge of its grid counts as implausible too (the
  // optimum lies outside the physical range searched).
  bool require_plausible = false;
  // The weaker rule every diagnosis keeps (require_plausible implies it):
  // refuse a candidate whose main parameter, when it is a shape, sits on the
  // edge of its grid (the optimum lies outside the range the library calls
  // physical: a "reflex" pinned to the 20 ms edge is a faster effect), or
  // none of whose gains has its physical sign (a stretch reflex that
  // assists stretch in both directions is not a stretch reflex; friction
  // that drives the motion is not friction). Point values, as
  // require_plausible; the sizes of the gains are not checked (some bounds
  // are guesses: K2) and the other gains and shapes may sit outside (a true
  // reflex's unstretched direction is often a little below 0, its damping at
  // the grid's 1.0). Measured: docs/diagnosis.md, "Torque-channel lag".
  // Since 2026-12-06 also refused: a candidate with a gain of the wrong
  // sign beyond its 95 % Wald interval (cluster-robust SE) that exceeds a
  // quarter of its largest right-sign gain (a "reflex" that pushes the same
  // way for motion in either direction is direction-blind, not a reflex;
  // true reflexes leaked at most 0.16 in the study: docs/diagnosis.md).
  bool require_physical = true;
  // Among the significant candidates accept the one with the largest t
  // statistic of the fold gains (most consistent held-out improvement) instead
  // of the largest mean gain: a mechanism with many free gains can reach a
  // mean gain similar to the true one's by fitting a few trials well.
  bool rank_by_t = false;
  // Parsimony among the significant candidates (the "one-standard-error
  // rule" of cross-validated model choice, Breiman et al. 1984, Hastie,
  // Tibshirani & Friedman 2009 §7.10): the candidate with the fewest free
  // parameters (shape + gains) whose fold gains are within one standard error
  // of the best candidate's (paired over folds) is accepted. A flexible
  // mechanism (the 7-gain reflex) otherwise wins by fitting a one-gain
  // mechanism's signature nearly as well (Δx(t − τ) and Δẋ(t − τ) span
  // Δẍ-like shapes), and names the wrong cause.
  bool prefer_simpler = false;
  // Keep the held-out predictions of the baseline and the extended model
  // (Diagnosis::predictions; --plots and the JSON "traces").
  bool keep_predictions = false;
};

struct Interval {
  double value = 0.0, lo = 0.0, hi = 0.0;  // estimate and 95 % percentile interval
};

struct ParamEstimate {
  std::string name, unit;
  Interval est;
  double plausible_lo = 0.0, plausible_hi = 0.0;
  bool has_bounds = false;
  bool shape = false;  // searched on a grid bounded by [plausible_lo, plausible_hi]
  // An interval end beyond the points profiled (a shape's profile
  // likelihood, stats::signed_root_interval): the end is at least that far out.
  bool lo_open = false, hi_open = false;
  [[nodiscard]] bool plausible() const {
    return !has_bounds || (est.value >= plausible_lo && est.value <= plausible_hi);
  }
  // A shape estimate on the edge of its search range: the optimum may lie outside it.
  [[nodiscard]] bool at_edge() const {
    const double tol = 1e-9 * std::max(std::fabs(plausible_lo), std::fabs(plausible_hi));
    return shape && (std::fabs(est.value - plausible_lo) <= tol || std::fabs(est.value - plausible_hi) <= tol);
  }
};

struct CandidateScore {
  std::string id, title, signature, not_applicable;
  std::vector<double> fold_gain;  // relative held-out SSE reduction per fold
  stats::OneSidedT test;
  double p_holm = 1.0;
  bool significant = false;
  bool implausible = false;  // significant or not: a parameter outside its plausible range (require_plausible)
  std::vector<ParamEstimate> params;  // fitted on all data (no interval)
  std::vector<double> setting;        // chosen shape parameters on all data
  // The main shape parameter chosen on each fold's training blocks (empty
  // without a shape grid): how firmly the data place it.
  std::vector<double> fold_main;
  // Detection limit of this session for this mechanism (docs/diagnosis.md,
  // "Detection limits"), one entry per gain at the chosen shape: the
  // cluster-robust standard error of the gain (clusters = the bootstrap
  // units: trials, or blocks of a record) and the smallest |gain| a one-sided
  // test at alpha/m (m applicable candidates of the round) detects with 90 %
  // power, (z_{1-alpha/m} + z_0.9) SE. It is the limit of an in-sample Wald
  // test; the cross-validated decision is more conservative (the study in
  // docs/diagnosis.md measures by how much). SE scales as 1/sqrt(units).
  std::vector<double> gain_se, gain_mde;
  int clusters = 0;
};

struct Round {
  std::vector<CandidateScore> candidates;
  int accepted = -1;  // index into candidates
};

struct CrossCorr {
  std::string regressor;
  double rho = 0.0;    // largest |correlation| (signed) over the lags searched
  double lag_s = 0.0;  // its lag (regressor delayed by lag)
  double bound = 0.0;  // 95 % bound (Bartlett variance, Bonferroni over lags)
  bool significant = false;
};

struct Signatures {
  double resid_rms = 0.0, skewness = 0.0, skewness_se = 0.0, excess_kurtosis = 0.0, kurtosis_se = 0.0;
  int decimation = 1;  // residual decimated to the smoother's bandwidth for these statistics
  stats::LjungBox ljung_box;
  std::vector<CrossCorr> xcorr;
};

struct HeldOut {
  Interval vaf;    // 1 - SSE / SST over held-out folds, pooled
  Interval nrmse;  // sqrt(SSE / SST)
  std::vector<double> fold_vaf;
};

// Held-out predictions of the target: every usable sample predicted by the
// model fitted on the other folds, exactly as the engine scores the folds
// (the last accepted mechanism's shape chosen per fold on the training folds,
// the earlier ones at their full-data shape).
struct HeldOutPredictions {
  struct Span {
    std::size_t seg = 0, begin = 0, end = 0;  // samples [begin, end) of segment seg
    int fold = 0;
  };
  std::vector<Span> spans;                            // the engine's blocks
  std::vector<std::vector<double>> baseline, extended;  // [segment][sample], NaN outside the spans; extended empty without a misfit
};

struct Diagnosis {
  std::string source;
  std::size_t n_used = 0;
  double duration_s = 0.0;
  int folds = 0, blocks = 0;
  double guard_s = 0.0;
  std::vector<ParamEstimate> baseline_params;
  HeldOut baseline_heldout;
  Signatures before, after;
  std::vector<Round> rounds;
  std::vector<std::string> accepted;        // mechanism ids, in the order added
  std::vector<std::vector<double>> accepted_settings;  // the search rounds' shapes (grid points)
  // Each accepted mechanism's shape in the extended model as reported
  // (searched off the grid where the mechanism allows it; empty when no
  // final fit was made): shape_of(a) is the one to build its columns from.
  std::vector<std::vector<double>> final_settings;
  [[nodiscard]] const std::vector<double>& shape_of(std::size_t a) const {
    return a < final_settings.size() ? final_settings[a] : accepted_settings.at(a);
  }
  std::vector<ParamEstimate> final_params;  // base then each accepted mechanism's shape params and gains
  // Sums of a baseline parameter and an accepted gain that mean something
  // physical (Mechanism::base_sum: K + dK of a relaxing stiffness), with
  // their block-bootstrap intervals; meaning says what.
  struct Derived {
    ParamEstimate param;
    std::string base;  // the baseline parameter it adds to
    std::string meaning;
  };
  std::vector<Derived> derived_params;
  HeldOut final_heldout;
  Interval heldout_gain;                    // 1 - SSE_after / SSE_before over held-out folds
  // RMS (about its mean) of each accepted mechanism's term in the extended
  // model, and of the target: "how much of the torque is the reflex".
  std::vector<double> contribution_rms;
  double target_rms = 0.0;
  HeldOutPredictions predictions;  // EngineOptions::keep_predictions
  double seconds = 0.0;
  [[nodiscard]] bool misfit_found() const { return !accepted.empty(); }
  [[nodiscard]] const ParamEstimate* find_final(const std::string& name) const;
  [[nodiscard]] const ParamEstimate* find_baseline(const std::string& name) const;
};

// One block of the cross-validation design: samples [begin, end) of segment
// seg, held out with fold `fold`, resampled by the bootstrap as unit `unit`
// (a trial: both axes of a planar trial share it).
struct CvBlock {
  std::size_t seg = 0, begin = 0, end = 0;
  int fold = 0;
  std::size_t unit = 0;
};

// The design every stage of a diagnosis scores on (docs/diagnosis.md,
// "Pipeline" 3): folds of neighbouring trials, or of one continuous record
// cut into opt.folds folds of opt.blocks_per_fold blocks with guard gaps,
// after `history` samples. Throws manip::InputError when the data are too
// short (the message says how long they must be).
[[nodiscard]] std::vector<CvBlock> cv_blocks(const Dataset& d, const EngineOptions& opt, std::size_t history);

// Throws manip::InputError (exit 4) when the data cannot support the
// cross-validation (message says how much is needed).
[[nodiscard]] Diagnosis diagnose(const Dataset& d, const std::vector<std::unique_ptr<Mechanism>>& library,
                                 const EngineOptions& opt = {});

}  // namespace manip::diagnosis
