#pragma once
// The manipulandum front end of diagnose_model (docs/diagnosis.md,
// "Manipulandum sessions"): session logs of manip_rt / manip_sim in, the
// engine's dataset out.
//
// Per perturbed trial the estimator's own code assembles the trial
// (estimation::TrialAssembler), isolates the variational signals over
// [onset, onset + T_est] (estimation::isolate_variational: SG jerk, high-pass,
// integration; paper §3.1) and gives Δu_ext by eq. 21; M_BSP is eq. 16 at the
// onset position, fixed as in the estimator. The baseline is eq. 14,
//   Δu_ext − M_BSP Δẍ = D Δẋ + K Δx,     D full, K symmetric,
// written as two scalar equations per sample (one per shoulder-frame axis,
// two segments per trial sharing the trial as cross-validation unit) with
// seven shared columns: D11, D12, D21, D22, K11, K12 (= K21), K22.
//
// Truth channels (MANIP_TRUTH_STATE, MANIP_TRUTH_IMPEDANCE) are never read:
// LogCollector drops them before the assembler sees the stream.
#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "manip/diagnosis/dataset.hpp"
#include <nlohmann/json.hpp>

#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/mechanisms.hpp"
#include "manip/diagnosis/sensor_delay.hpp"
#include "manip/estimation/settings.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/logging/session_stream.hpp"

namespace manip::diagnosis {

// One session's perturbed trials as the estimator assembles them.
struct CollectedSession {
  std::string name;  // the log's path as given
  estimation::SessionInfo info;
  bool has_session = false;
  std::vector<estimation::TrialData> perturbed;
  int n_trials = 0;
  std::vector<estimation::TrialIssue> issues;
  std::vector<std::string> warnings;
};

// Feeds a message stream (a log, or a simulation run in a test) to the
// estimator's TrialAssembler, without the truth channels.
class LogCollector final : public logging::SessionHandler {
 public:
  explicit LogCollector(CollectedSession& out);
  void on_session(const manip::session_t& m) override { asmb_.on_session(m); }
  void on_state(const manip::state_t& m) override { asmb_.on_state(m); }
  void on_trial_event(const manip::trial_event_t& m) override { asmb_.on_trial_event(m); }
  void on_warning(const std::string& w) override { asmb_.on_warning(w); }
  // on_truth_state / on_truth_impedance: deliberately not forwarded (the
  // diagnosis sees what a lab log shows).
  // Releases the last trial and copies the session, issues and warnings.
  void finish();
  [[nodiscard]] std::int64_t states_seen() const { return asmb_.states_seen(); }

 private:
  CollectedSession& out_;
  estimation::TrialAssembler asmb_;
};

// Reads a log through a LogCollector. Throws manip::InputError (exit 4).
[[nodiscard]] CollectedSession collect_log(const std::string& path);

// The v_s grid of the stage_friction mechanism (m/s): 0.25-16 mm/s, log-spaced.
inline constexpr std::array<double, 7> kStageFrictionVs = {0.00025, 0.0005, 0.001, 0.002, 0.004, 0.008, 0.016};

// Stage friction through the isolation (the stage_friction column before the
// nuisance projection): for each v_s of kStageFrictionVs, the series
// tanh(v_ws / v_s) per workspace axis (v the trial's admittance reference
// velocity, the whole trial), rotated to the shoulder frame by `ws_to_sh`,
// isolated exactly as the trial's acceleration is (estimation::isolate_variational:
// SG jerk of its double integral, high-pass, integration from onset), over
// [onset, onset + T_est]. Derivation in manipulandum.cpp (StageFriction).
[[nodiscard]] std::vector<std::vector<Eigen::Vector2d>> isolated_stage_friction(const estimation::SessionInfo& info,
                                                                               const estimation::TrialData& trial,
                                                                               const estimation::PipelineSettings& pipeline,
                                                                               const Eigen::Matrix2d& ws_to_sh);

struct PlanarOptions {
  estimation::EstimatorSettings estimator{};  // pipeline (SG, high-pass, T_est) and pem settings as estimate_impedance's defaults
  bool pem_baseline = true;  // also fit the estimator's default method (pem) for the report
  // Order of the per-trial, per-axis nuisance polynomial projected out of the
  // target and every column (the unperturbed movement the high-pass leaves in
  // the window; -1: none). 1 (offset and slope): measured against 0 and 3 on
  // hidden sessions (docs/diagnosis.md); a cubic removes most of the
  // perturbation response itself from a 150 ms window.
  int nuisance_order = 1;
  // Add the direction-dependent reflex to the library (off by default: its
  // rectified copy's even half also fits a residual common to every trial
  // along the reach, which named it in 2 of 20 clean sessions;
  // docs/diagnosis.md, "Direction-dependent reflex").
  bool directional_reflex = false;
  // The library's mechanisms by id (empty: all of them): a confirmatory
  // test of chosen causes (diagnose_model --mechanisms), each greedy round's
  // Holm correction over them only; fewer candidates also cost fewer
  // likelihood fits. run_planar throws std::invalid_argument naming an id
  // the library does not have.
  std::vector<std::string> mechanisms;
};

// The estimator's default method fitted on the same trials (for the report).
struct PemBaseline {
  bool available = false;
  std::string method, error;
  Eigen::Matrix2d d = Eigen::Matrix2d::Zero(), k = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d d_lo = Eigen::Matrix2d::Zero(), d_hi = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d k_lo = Eigen::Matrix2d::Zero(), k_hi = Eigen::Matrix2d::Zero();
  double neg_log_likelihood = 0.0;  // pem only (0 otherwise)
  bool has_likelihood = false;
  estimation::DisturbanceModel noise{};  // pem: the fitted model of the person's own motion and noise (when has_likelihood)
};

// The extension's amplitude refined by the default method's likelihood: the
// correction u_pert − α C (C from the equation-error gains) with α chosen by
// golden-section search on [0, 2] for the smallest negative log-likelihood
// of the default method (pem: the exact Gaussian likelihood of the raw
// positions, its noise model included). α = 1 keeps the equation-error gains.
struct RefinedExtension {
  bool available = false;
  double alpha = 1.0;
  double nll_baseline = 0.0, nll_alpha1 = 0.0, nll_best = 0.0;
  int evaluations = 0;
  PemBaseline fit;  // the default method at α
};
// What the encoder route showed before the diagnosis moved to the reference.
struct TrackingSwitch {
  bool switched = false;
  double share = 0.0, coef = 0.0;  // SensorDelay::tracking_share, tracking_coef on the encoder
  double heldout_share = 0.0;      // SensorDelay::tracking_heldout_share (leave one trial out)
  int heldout_better = 0;          // trials left out whose residual the column lowered
  int trials = 0;                  // trials in the sensor's fit
  double rms_um = 0.0;             // x_ref − x RMS over the windows (TrackingSummary)
  int shift0 = 0, shift1 = 0;      // trials whose reference was aligned by 0 and by 1 sample
  PemBaseline on_encoder;          // the default method on the encoder
  // The default method with the tracking as a known force on the loop, the
  // encoder as the person's position (estimate_impedance --position-source
  // tracked, estimation/tracking_input.hpp): the estimate to prefer when the
  // stages lag far (docs/estimator.md, "Which position"). Reported beside
  // the reference's; the search itself runs on the reference.
  PemBaseline on_tracked;
};
// The rule: tracking takes at least this share of the disagreement, with a
// coefficient within this distance of 1 (the header of sensor_delay.hpp),
// and lowers the disagreement on held-out trials (a positive held-out share).
inline constexpr double kTrackingMinShare = 0.5, kTrackingCoefTolerance = 0.2;

struct PlanarPrepared {
  Dataset data;
  // For the estimator's default method (through the method registry), per
  // used trial in the order of data.planar.
  estimation::SessionInfo info;
  estimation::EstimatorSettings settings;
  std::vector<estimation::VariationalWindow> vw;
  std::vector<Eigen::Matrix2d> m_bsp;
  std::vector<estimation::OeWindow> oe, pw;
  std::vector<std::string> logs;
  int n_trials = 0, n_perturbed = 0;
  std::vector<std::string> excluded;  // "log: trial k: reason"
  PemBaseline pem;          // default method, no extension
  PemBaseline pem_extended; // default method refitted with the accepted extension (filled by the app/tests)
  RefinedExtension refined; // ... with its amplitude refined by the likelihood (filled by the app/tests)
  // The actuation delay read from the force sensor (sensor_delay.hpp); the
  // likelihood check's correction of a named delay takes it (likelihood_stage.hpp).
  SensorDelay sensor_delay;
  // Tracking (docs/diagnosis.md, "Tracking"): set by run_planar when the
  // stages' tracking of the admittance reference was most of eq. 21's
  // disagreement with the sensor on the encoder, and everything here was
  // then prepared with the reference as the position.
  TrackingSwitch tracking;
  double t_est_s = 0.0;
  int sg_window = 0;
};

// prepare_planar, then, where the stages follow the admittance reference
// through a PD (manip_rt), eq. 21 on the encoder carries M_adm Δë + D_adm Δė
// of the tracking error e = x_ref − x into every fit: when that term takes
// at least kTrackingMinShare of eq. 21's disagreement with the force sensor
// with a coefficient within kTrackingCoefTolerance of 1 (SensorDelay), the
// sessions are prepared again with the reference as the position (as
// --position-source reference) and PlanarPrepared::tracking says what the
// encoder showed (docs/diagnosis.md, "Tracking"). With opt.estimator.position
// already reference, prepare_planar alone.
[[nodiscard]] PlanarPrepared prepare_planar_tracked(std::vector<CollectedSession>& sessions, const PlanarOptions& opt, int folds,
                                                    const std::function<void(const std::string&)>& progress = {});

// Tracking over the used trials (PlanarTrial::x_track, reference_shift):
// trials with a reference, how they were aligned, the RMS of x_ref − x over the windows.
struct TrackingSummary {
  int trials = 0, shift0 = 0, shift1 = 0;
  double rms_um = 0.0;
};
[[nodiscard]] TrackingSummary tracking_summary(const PlanarPrepared& prep);

[[nodiscard]] RefinedExtension refine_with_default_method(const PlanarPrepared& prep,
                                                          const std::vector<std::vector<Eigen::Vector2d>>& correction,
                                                          const std::function<void(const std::string&)>& progress = {});

// The estimator's default method (method registry) on the used trials, its
// noise model included; with `correction` (per used trial, per sample of the
// window [onset, onset + T_est]) the perturbation force it is given becomes
// u_pert − correction: an extension that is linear in the variational signals
// (delayed u_pert, friction force, curl, handle mass, reflex) moved to the
// input side with the gains of the equation-error fit.
// `trials` (indices into the used trials): fit on these only (cross-validation), default all.
// `start`: a neighbouring fit to start the iteration from (pem: warm start; same optimum, fewer iterations).
[[nodiscard]] PemBaseline fit_default_method(const PlanarPrepared& prep,
                                             const std::vector<std::vector<Eigen::Vector2d>>* correction = nullptr,
                                             const std::vector<std::size_t>* trials = nullptr,
                                             const PemBaseline* start = nullptr);
// The default method's windows with `correction` applied (as fit_default_method gives them to the method).
[[nodiscard]] std::vector<estimation::OeWindow> corrected_pem_windows(const PlanarPrepared& prep,
                                                                     const std::vector<std::vector<Eigen::Vector2d>>* correction);

// The extended model's correction of u_pert per used trial: Σ gain × column
// over the accepted mechanisms, gains from the full-data equation-error fit.
// With alpha: every gain × alpha (the actuation delay exact: u(t) − u(t − alpha τ)).
[[nodiscard]] std::vector<std::vector<Eigen::Vector2d>> extension_correction(const Dataset& d, const Diagnosis& dg,
                                                                            const std::vector<std::unique_ptr<Mechanism>>& lib,
                                                                            double alpha);
[[nodiscard]] std::vector<std::vector<Eigen::Vector2d>> extension_correction(const Dataset& d, const Diagnosis& dg,
                                                                            const std::vector<std::unique_ptr<Mechanism>>& lib);

// The same with the correction rebuilt at every α by extension_correction(…, α)
// (exact actuation delay); the form diagnose_model uses.
[[nodiscard]] RefinedExtension refine_with_default_method(const PlanarPrepared& prep, const Diagnosis& dg,
                                                          const std::vector<std::unique_ptr<Mechanism>>& lib,
                                                          const std::function<void(const std::string&)>& progress = {});

// Refuses (InputError, exit 4) logs whose session configurations differ
// (names both logs and the first differing field), never pools them; and
// sessions with fewer usable perturbed trials than `folds` ("N usable
// perturbed trials; the cross-validation over trials needs at least K").
[[nodiscard]] PlanarPrepared prepare_planar(std::vector<CollectedSession>& sessions, const PlanarOptions& opt, int folds);

// Empty when the two sessions may be pooled, else "field: a vs b".
[[nodiscard]] std::string configuration_difference(const estimation::SessionInfo& a, const estimation::SessionInfo& b);

// The manipulandum's mechanism library (docs/diagnosis.md lists signatures and bounds).
[[nodiscard]] std::vector<std::unique_ptr<Mechanism>> planar_library(bool with_time_varying = false, bool with_directional_reflex = false);
// The same, each mechanism's columns projected like a dataset prepared with
// PlanarOptions::nuisance_order (use the same order).
[[nodiscard]] std::vector<std::unique_ptr<Mechanism>> planar_library(int nuisance_order, bool with_time_varying = false,
                                                                     bool with_directional_reflex = false);
// The short-latency reflex's gain g against the intrinsic D, K from its share
// of the apparent impedance g_app = g / (1 + g) (the library's gain_apparent):
// g = g_app / (1 − g_app), the share capped at 0.9 (≥ 1 would be a reflex
// without an intrinsic part).
[[nodiscard]] double reflex_intrinsic_gain(double share);

// Least-squares projection of the delayed variational signals onto the
// undelayed ones over the window (all planar trials, both axes):
// Δx(t − τ) ≈ a_x Δx + b_x Δẋ, Δẋ(t − τ) ≈ a_v Δx + b_v Δẋ. The fit of
// D, K absorbs a delayed force term along these (the delayed copies' fixed
// point, PlanarReflex::next_reference). Default (no data): τ = 0.
struct DelayedProjection {
  double a_x = 1.0, b_x = 0.0, a_v = 0.0, b_v = 1.0;
};
[[nodiscard]] DelayedProjection delayed_projection(const Dataset& d, double tau_s);

// D and K from a planar fit's parameter vector (first 7 entries: D11 D12 D21
// D22 K11 K12 K22) plus the accepted mechanisms' corrections that belong to
// the impedance (curl: K12 += c, K21 −= c).
struct PlanarImpedance {
  Eigen::Matrix2d d = Eigen::Matrix2d::Zero(), k = Eigen::Matrix2d::Zero();
};
[[nodiscard]] PlanarImpedance baseline_impedance(const Diagnosis& dg);
[[nodiscard]] PlanarImpedance final_impedance(const Diagnosis& dg);

// Residual RMS per time window after onset (both axes pooled), of the
// baseline and of the extended model, each as a share of the target's RMS in that window.
struct WindowMisfit {
  double t0_s = 0, t1_s = 0;
  double target_rms = 0, resid_before = 0, resid_after = 0;
  // Mean residual (signed) per axis: a systematic misfit shows as a bias in one window.
  double mean_before[2] = {0, 0}, mean_after[2] = {0, 0};
};
[[nodiscard]] std::vector<WindowMisfit> window_misfit(const Dataset& d, const Diagnosis& dg,
                                                      const std::vector<std::unique_ptr<Mechanism>>& lib,
                                                      const std::vector<double>& edges_s);

// Disagreement of eq. 21 with the force sensor (Δu_ext_adm − Δu_ext_force),
// RMS as a share of Δu_ext's RMS, and its correlation with the apparatus
// mechanisms' columns: apparatus mechanisms (delay, friction) make the two
// routes disagree, person-side mechanisms do not.
struct SensorDisagreement {
  double rms_share = 0.0;
  std::vector<std::pair<std::string, double>> rho;
};
[[nodiscard]] SensorDisagreement sensor_disagreement(const Dataset& d);

// The front end's sections of the report: data used, D and K before -> after
// (equation error) beside the estimator's default method, misfit per time
// window after onset, and the force-sensor disagreement.
struct PlanarReport {
  std::string text;
  nlohmann::json json;
};
[[nodiscard]] PlanarReport planar_report(const PlanarPrepared& prep, const Diagnosis& dg,
                                         const std::vector<std::unique_ptr<Mechanism>>& lib);

// Windows after onset of the misfit table [s]: before, during and after the
// short-latency reflex's arrival (the paper's T_est is 0.15 s; with --t-est
// longer the last edge grows).
[[nodiscard]] std::vector<double> default_window_edges(double t_est_s);

// A linear extension of the variational model (eq. 19-21 + eq. 9) as the
// true plant of a model-based correction (Mechanism::model_correction): the
// person's force on the handle gets
//   −(ΔM Δẍ + ΔK Δx + ΔD_τ Δẋ(t − τ) + ΔK_τ Δx(t − τ)),
// and with sensor_lag_s > 0 the admittance renders from a first-order
// lagged reading f_r of the force the sensor bears (τ_s ḟ_r = f_s − f_r).
struct LinearExtension {
  Eigen::Matrix2d mass_kg = Eigen::Matrix2d::Zero(), stiffness_npm = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d damping_delayed_nspm = Eigen::Matrix2d::Zero(), stiffness_delayed_npm = Eigen::Matrix2d::Zero();
  double delay_s = 0.0;  // of the delayed terms (≥ one sample when they are used)
  // One-sided delayed terms (unit w; zero: none): of the delayed force
  // c = D_d Δẋ(t − τ) + K_d Δx(t − τ) only delayed_gain × w max(0, wᵀ c)
  // acts: a muscle group along w, stretched by a deviation along w
  // (the direction-dependent reflex). Otherwise delayed_gain × c.
  Eigen::Vector2d delayed_one_sided_along = Eigen::Vector2d::Zero();
  double delayed_gain = 1.0;
  double sensor_lag_s = 0.0;
};
// The correction of u_pert that makes the baseline variational model
// (M_BSP + M_adm + M_handle, D + D_adm, K) reproduce the extended plant's
// response to u_pert from rest at onset: e = u − M_tot Δẍ − (D + D_adm) Δẋ − K Δx
// along the simulated response, averaged over each sample's hold (RK4, 8
// steps per sample), per planar trial. A trial whose extended inertia is not
// positive definite gets no correction (outside every mechanism's bounds).
[[nodiscard]] std::vector<std::vector<Eigen::Vector2d>> simulate_extension(
    const Dataset& d, const Eigen::Matrix2d& d_nspm, const Eigen::Matrix2d& k_npm,
    const std::function<LinearExtension(const PlanarTrial&)>& extension);

// Force-sensor lag (src/diagnosis/planar_sensor.cpp; docs/diagnosis.md,
// "Force-sensor mechanisms"): column d/dt (u_pert − Δu_ext(21) − M_handle Δẍ) − u̇_pert
// = d/dt Δf_r (the reading's variation), gain tau [s]. The dataset does not
// carry M_handle: the library's instance takes the schema's 0.25 kg.
[[nodiscard]] std::unique_ptr<Mechanism> make_force_sensor_lag(double m_handle_kg = 0.25);

}  // namespace manip::diagnosis
