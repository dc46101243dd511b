#pragma once
// The likelihood check of the manipulandum diagnosis (docs/diagnosis.md,
// "Likelihood check"): every candidate of the mechanism library scored by the
// estimator's default method (`pem`: the exact Gaussian likelihood of the raw
// positions with its model of the person's own motion and motor noise).
//
// Why a second stage: the equation-error search (engine.hpp) works on the
// isolated, differentiated signals, whose noise is large and coloured; a
// mechanism that the constant D, K absorbs to first order (curl stiffness
// against the antisymmetric part of D, a delayed reflex) leaves too small an
// equation-error residual to be found in 24 trials. The likelihood of the raw
// positions uses the same data far more efficiently: on one hidden-curl
// session (seed 3) the equation-error detection limit for c is 59 N/m while
// the likelihood ratio for the hidden 40 N/m is 8.2 (p = 0.004).
//
// Each candidate m is a one-parameter family of corrections of the
// perturbation force, u_pert − C_acc − α C_m, where C_m is the mechanism's
// correction with its equation-error gains and shape (extension_correction),
// or with the direction and shapes the mechanism sets itself
// (Mechanism::likelihood_plan), simulated from the model at the fit's D, K
// when the mechanism is linear in the variational state
// (Mechanism::model_correction: free of the noise that columns built from
// the isolated signals carry into the input), and C_acc the already
// accepted ones at their fitted amplitudes; D, K and the noise model are
// re-fitted at every α (profile likelihood). The
// likelihood ratio LR = 2 (NLL(0) − min_α NLL(α)) is referred to χ² with as
// many degrees of freedom as the candidate's equation-error parameters
// (shape + gains: the direction C_m was itself fitted to these data), so a
// flexible mechanism pays for its flexibility; Holm over the round's
// candidates at level alpha; the accepted mechanism must keep plausible
// parameters (α × gains inside their bounds, shapes not on the edge of their
// grid). Greedy rounds until no candidate is significant.
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/stats.hpp"

namespace manip::diagnosis {

// Profile of the negative log-likelihood in the amplitude α (D, K and the
// noise model re-fitted at every α). The correction enters the model's input
// linearly, so NLL(α) is close to a parabola: α = 0 (given), 1, then 2 or −1
// towards the descent, then two steps, α clamped to [−2, 3]:
// - the best point between two profiled ones (bracketed): the parabola
//   through the best and its neighbours in α where its vertex falls inside,
//   else, or after a parabolic step that did not lower the NLL, a
//   golden-section step into the longer side (Brent's safeguard);
// - the best at an end of the profiled range: the parabola through the three
//   best (an extrapolation) where it bends upwards; where it bends the other
//   way (the descent steepens towards the best) one step outward by the best's
//   distance to the nearest other point, and one more step after it.
// On near-parabolic profiles (realistic noise) the three best are the bracket
// and every step is the plain parabolic one. The delayed copies' profiles are
// far from parabolic (a one-sided copy's intrinsic gain is α/(4 − α)): hidden
// directional reflex 1.5, seed 5003, NLL −30 659.9, −30 674.8, −30 695.1 at
// α = 0, 1, 2 bend downwards and the profile used to end at α = 2 (gain 1.00
// against the hidden 1.5; docs/diagnosis.md, "Amplitude profile"). Noise-free
// sessions' `pem` fits converge loosely off the optimum (NLL 0, +266, +246 at
// α = 0, 1, −1, then +1 289 at α = 0.36): there an outward step from an
// interior best only cost fits (a noise-free test 311 → 401 s), the bracket
// steps do not (227 s).
// alpha_min: the amplitude's lower bound (a one-sided mechanism's negative
// amplitude is its opposite direction, profiled on its own).
struct AmplitudeProfile {
  double alpha = 0.0;
  PemBaseline fit;
  int evaluations = 0;
  // 95 % profile-likelihood half-width in α (stats::profile_interval; NaN
  // when the profile is not convex around its best points).
  double half_width = std::numeric_limits<double>::quiet_NaN();
};
AmplitudeProfile profile_amplitude(const std::function<PemBaseline(double)>& eval, const PemBaseline& fit0, double alpha_min = -2.0);

struct LikelihoodCandidate {
  std::string id;
  std::vector<double> setting;  // shape, from the equation-error search
  int df = 1;                   // shape + gains of the mechanism
  double alpha = 0.0;           // amplitude at the likelihood optimum (1 = equation-error gains)
  double nll0 = 0.0, nll = 0.0, lr = 0.0, p = 1.0, p_holm = 1.0;
  bool significant = false, plausible = true;
  std::string implausible_reason;
  // Practical relevance: the largest change of a D or K element (curl
  // included in K) that modelling the mechanism makes, in units of that
  // element's 95 % half-width in the corrected estimate. A significant
  // mechanism that moves no element by its own uncertainty (relevance < 1)
  // is reported as "significant, negligible" and not named: it does not
  // change what the lab measures (seen on clean sessions: an inertia a few
  // per cent off the a-priori M_BSP, LR 7-9).
  double relevance = 0.0;
  // Shape params, then α × gains with the 95 % profile-likelihood interval of
  // α (stats::profile_interval; for accepted candidates after the joint
  // refit, each amplitude's profile with the others fixed). The first shape
  // parameter of a plan-profiled candidate (the reflexes' and the early
  // feedback's delay) has the interval of its own profile over the values
  // searched, the amplitude refitted at each (stats::signed_root_interval;
  // lo_open / hi_open where it reaches past them); other shapes lo = hi.
  std::vector<ParamEstimate> params;
  // Where an accepted candidate's parameters come from when not from its
  // amplitude profile: "force sensor" for a named actuation delay whose
  // sensor reading is usable (then params hold that reading and its
  // bootstrap interval; sensor_delay.hpp).
  std::string source;
  PemBaseline fit;                    // default method at the optimum (accepted ones included)
  // Accepted candidates only: cross-validation over trials (folds of
  // neighbouring trials, as the equation-error search): per fold, both models
  // fitted on the other trials (the amplitude profiled there, and a shaped
  // candidate's shape searched there as in the rounds), the held-out
  // trials' negative log-likelihood at those fits (pem.hpp,
  // window_neg_log_likelihood); gain = NLL_without − NLL_with per held-out
  // trial [nats], one-sided t over folds.
  std::vector<double> fold_gain_nats;
  // The shape each fold's training trials chose (candidates whose plan
  // profiles more than one shape; empty otherwise).
  std::vector<std::vector<double>> fold_settings;
  stats::OneSidedT heldout;
  bool heldout_done = false;
  // From the second round on the held-out check decides: a further mechanism
  // is named only when it adds a significant held-out gain (p < α); else the
  // greedy search stops there (false second names, docs/diagnosis.md).
  bool heldout_rejected = false;
};

struct LikelihoodRound {
  std::vector<LikelihoodCandidate> candidates;
  int accepted = -1;
};

struct LikelihoodStage {
  bool available = false;
  std::string error;  // why not (no likelihood from the default method, …)
  double alpha_level = 0.05;
  std::vector<LikelihoodRound> rounds;
  std::vector<std::string> accepted;   // in the order added
  std::vector<LikelihoodCandidate> accepted_fits;
  double nll_baseline = 0.0, nll_final = 0.0;
  PemBaseline fit;  // the default method with every accepted correction (the corrected estimate)
  int evaluations = 0;
  [[nodiscard]] bool misfit_found() const { return !accepted.empty(); }
  // D, K of the corrected estimate, curl included in K when accepted.
  [[nodiscard]] PlanarImpedance impedance() const;
};

// folds: of the held-out check of each accepted candidate (0: none).
[[nodiscard]] LikelihoodStage likelihood_stage(const PlanarPrepared& prep, const Diagnosis& dg,
                                               const std::vector<std::unique_ptr<Mechanism>>& lib, double alpha = 0.05,
                                               int folds = 10, const std::function<void(const std::string&)>& progress = {});

[[nodiscard]] std::string likelihood_text(const LikelihoodStage& s);
[[nodiscard]] nlohmann::json likelihood_json(const LikelihoodStage& s);

// The diagnosis' answer: the causes named by the likelihood check when the
// default method has a likelihood (it uses the data more efficiently and
// decides), else by the equation-error search; with the corrected D, K and,
// when nothing was named, the session's detection limits.
// An explanation the session cannot tell apart from a named one (so the
// report names both): within T_est a short-latency reflex of gain g at
// delay τ acts as an inertia change ΔM = g (τ²K/2 − τD) (docs/diagnosis.md,
// "The short-latency reflex in a 150 ms window"), so a named inertia
// reduction (M_BSP or handle mass below the configured) is also a reflex
// of the gain that gives the same ΔM.
struct Alternative {
  std::string named;  // the named mechanism it stands next to
  std::string id;     // the alternative mechanism
  double gain = 0.0;  // its equivalent gain (reflex: × intrinsic impedance)
  double delay_s = 0.0;
  std::string why;
};
struct Conclusion {
  std::string decided_by;  // "likelihood" or "equation_error"
  std::vector<std::string> named;
  // Per named mechanism (same order), its parameters as the deciding stage
  // has them (the likelihood check: joint amplitudes with 95 %
  // profile-likelihood intervals; the equation-error search: empty, its
  // bootstrap intervals are in its own section).
  std::vector<std::vector<ParamEstimate>> named_params;
  std::vector<std::string> named_sources;  // per named mechanism: "" (as above) or LikelihoodCandidate::source
  bool has_corrected = false;
  PlanarImpedance corrected;
  std::vector<Alternative> alternatives;
  // What the session's protocol cannot show (empty: nothing to say): under a
  // pulse of 100 ms or more a short-latency reflex is part of D, K within
  // the window unless named (docs/diagnosis.md, "Pulse").
  std::string protocol_note;
  // The stages' tracking, when run_planar moved the diagnosis to the
  // admittance reference (PlanarPrepared::tracking; empty otherwise).
  std::string tracking_note;
  // Then also the default method with the tracking as a known force on the
  // encoder (TrackingSwitch::on_tracked), without the named corrections.
  bool has_tracked = false;
  PlanarImpedance tracked;
};
[[nodiscard]] Conclusion conclude(const Diagnosis& dg, const LikelihoodStage& s, const PlanarPrepared& prep);
[[nodiscard]] std::string conclusion_text(const Conclusion& c, const Diagnosis& dg);
[[nodiscard]] nlohmann::json conclusion_json(const Conclusion& c);

}  // namespace manip::diagnosis

namespace manip::diagnosis {

// The whole manipulandum diagnosis as diagnose_model runs it: prepare the
// sessions' trials, the equation-error search (with the manipulandum's rules:
// plausible parameters, t ranking, parsimony), the default method refitted
// with its extension, the likelihood check and the conclusion.
struct PlanarRun {
  PlanarPrepared prep;
  std::vector<std::unique_ptr<Mechanism>> lib;
  Diagnosis dg;
  LikelihoodStage lk;
  Conclusion concl;
};
// heldout_folds: of the likelihood check's held-out check (-1: eo.folds, 0: none).
[[nodiscard]] PlanarRun run_planar(std::vector<CollectedSession>& sessions, const PlanarOptions& po, EngineOptions eo,
                                   bool with_time_varying = false, int heldout_folds = -1);

}  // namespace manip::diagnosis
