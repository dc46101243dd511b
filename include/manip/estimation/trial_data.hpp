#pragma once
// A session as the estimator sees it: the session message reduced to what the
// method needs, and each trial's samples from its START to its END event,
// converted once from the workspace frame of the log to the shoulder frame of
// the arm (common/frames.hpp).
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "manip/common/frames.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/model/arm.hpp"
#include "manip/schema/session_description.hpp"

namespace manip::estimation {

// The session as the estimator sees it is the one session description
// (schema/session_description.hpp): no second copy with its own defaults.
using SessionInfo = schema::SessionDescription;

// schema::from_message, refused with manip::InputError ("session message:
// <field>: <reason>", exit code 4) when invalid_reason() is set.
SessionInfo session_info_from(const manip::session_t& msg);

// Samples of one trial, shoulder frame, index 0 = the START cycle.
struct TrialData {
  int trial{-1};
  std::int64_t start_cycle{0};
  bool perturbed{false};
  double angle_rad{0.0};
  double amplitude_n{0.0};
  std::int64_t onset_index{-1};  // index of the ONSET cycle, -1 if none
  bool ended{false};             // END (not ABORT) seen
  std::vector<Vec2> x_m;         // measured handle position
  std::vector<Vec2> f_sensor_n;  // force of the hand side on the sensor
  std::vector<Vec2> u_pert_n;    // perturbation force command
  std::vector<Vec2> x_ref_m;     // admittance reference position
  std::vector<Vec2> xd_ref_m, xdd_ref_m;  // and its velocity, acceleration
  // Unperturbed twin (simulated logs only), same indices; empty otherwise.
  std::vector<Vec2> x_twin_m, xd_twin_m, xdd_twin_m;
  bool has_truth{false};
  Mat2 truth_m_kg{Mat2::Zero()}, truth_d_nspm{Mat2::Zero()}, truth_k_npm{Mat2::Zero()};
  std::string truth_model;
  [[nodiscard]] std::size_t size() const { return x_m.size(); }
};

// Which logged signal is the handle position x for the estimator
// (EstimatorSettings::position, `position_source` in the YAML,
// --position-source). encoder: the measured position (the paper's). reference:
// the admittance reference x_ref the controller integrated from the logged
// force (eq. 20), aligned to the encoder's samples. On a rig whose stages
// track the reference through a PD, eq. 21 holds exactly for the reference,
// and only approximately for the encoder: the tracking error e = x_ref − x
// enters Δu_ext as M_adm Δë + D_adm Δė (docs/diagnosis.md, "Tracking").
// tracked: the encoder as the person's position, and the tracking error as
// a known input: the admittance integrated x_ref = x + e, so the loop gets
// u_pert − M_adm ë − D_adm ė and eq. 21 the reference's kinematics for the
// admittance (exact on both sides, up to the isolation of e).
// automatic ("auto", the default): the reference on a controller's log
// (session_t.source "manip_rt…"), the encoder otherwise (resolved_position).
enum class PositionSource { encoder, reference, automatic, tracked };

// "encoder", "reference", "auto", "tracked" (the YAML's and the CLI's spelling).
const char* to_string(PositionSource p);
std::optional<PositionSource> parse_position_source(std::string_view s);

// The position a session's trials take: `automatic` is the reference on a
// controller's log (source "manip_rt/…", hardware or simulated stages: the
// stages track x_ref through a PD, and on them the reference put the default
// method's D within 2.2 % of the simulated person where the encoder left it
// 12 % off, median of 10 sessions; docs/estimator.md, "Which position") and
// the encoder otherwise: manip_sim's x_ref is its ideal handle, noise-free,
// and imported logs carry none.
PositionSource resolved_position(PositionSource requested, const std::string& source);

// The samples by which a log's x_ref leads the encoder, from the log's
// producer (session_t.source; lcmtypes/state_t.lcm): manip_sim and
// make_hidden_session ("manip_sim…") log the simulated handle itself at t_k
// (an ideal admittance): 0; a controller (manip_rt) logs the set-point for
// the next sample, t_k + T (control/admittance.hpp): 1. Not from the data:
// on simulated stages without friction, or with twice the PD's bandwidth,
// the handle runs so close to that set-point that the logged x_ref(k) is
// nearer x(k) than x_ref(k − 1) is, and the reference shifted by 0 put the
// default method's D22 32-50 % off, by 1 within 3 % (docs/diagnosis.md,
// "Tracking").
int reference_shift_for(const std::string& source);

// The reference aligned to the encoder's samples: x_ref(k − shift), the
// first sample of a shifted series extrapolated linearly. Throws
// std::invalid_argument naming the trial when its reference is missing or
// not finite (imported logs carry none).
std::vector<Vec2> aligned_reference(const TrialData& t, int shift);

// The session-level truth of a simulated log: one MANIP_TRUTH_IMPEDANCE with
// trial = -1 and model = "apparent" (docs/simulation.md, "Apparent-impedance
// truth"): the constant D, K (M_BSP fixed as the estimator takes it) that best
// fit the exact, noise-free variational signals over [0, t_est_s] after onset,
// pooled over the session's perturbed trials. It includes every pathway acting
// within the window (intrinsic + reflex: what the paper calls involuntary),
// unlike the per-trial intrinsic truth. Shoulder frame, SI units.
inline constexpr const char* kApparentTruthModel = "apparent";  // = sim::kApparentTruthModel (the writer)
struct ApparentTruth {
  Mat2 m_kg{Mat2::Zero()}, d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()};
  double t_est_s{0.0};
  std::string model;
};

// A trial that could not be used, and why (reported, never silently dropped).
struct TrialIssue {
  int trial{-1};
  std::string reason;
};

// Builds trials from a message stream and hands each complete trial to a
// callback as soon as its END has been put in order, so a session of any
// length is processed in bounded memory. Checks: session message first,
// gapless cycle counter within a trial, finite samples, onset inside the
// trial.
//
// Trials are assembled by the `cycle` each message carries, not by arrival
// order: messages are held in a reorder window and released in the order
// (cycle; within one cycle START, ONSET, the state, the truth twin state, the
// truth impedance, END/ABORT). So a writer may emit a trial event up to
// reorder_tolerance_cycles() cycles before or after the state of its cycle
// (e.g. START just after the trial's first state, END just before its last):
// the contract is in docs/schema.md ("Event order"). A message later than
// that is processed when it arrives and reported as out of order. Memory: at
// most kMaxPendingFactor x tolerance messages are held.
class TrialAssembler final : public logging::SessionHandler {
 public:
  using TrialCallback = std::function<void(const SessionInfo&, TrialData&&)>;
  // 0.1 s at 4 kHz: far more than any writer's skew between its state and
  // trial-event streams (a cycle for a third-party writer, a few ms for a bus
  // logger), small enough to hold in memory (~100 kB).
  static constexpr std::int64_t kDefaultReorderCycles = 400;
  static constexpr std::size_t kMaxPendingFactor = 8;

  explicit TrialAssembler(TrialCallback cb) : cb_(std::move(cb)) {}

  void on_session(const manip::session_t& msg) override;
  void on_state(const manip::state_t& msg) override;
  void on_trial_event(const manip::trial_event_t& msg) override;
  void on_truth_state(const manip::state_t& msg) override;
  void on_truth_impedance(const manip::impedance_truth_t& msg) override;
  void on_warning(const std::string& message) override { warnings_.push_back(message); }

  // false: for trials that START unperturbed keep only x_m (the estimator uses
  // nothing else of them: they only feed the PSD), which saves most of the
  // copying and memory of reading a session. Checks are unchanged. Default true.
  void set_keep_unperturbed_signals(bool keep) { keep_unperturbed_signals_ = keep; }
  // Set before the first message; >= 0 (0: every message must be in order).
  void set_reorder_tolerance_cycles(std::int64_t cycles) { tolerance_ = cycles < 0 ? 0 : cycles; }
  [[nodiscard]] std::int64_t reorder_tolerance_cycles() const { return tolerance_; }

  // Call after the stream ended: releases the messages still held in the
  // reorder window (the last trial's END among them) and reports a trial
  // left open. Required: without it the last trial is never handed over.
  void finish();

  [[nodiscard]] bool has_session() const { return has_session_; }
  [[nodiscard]] const SessionInfo& session() const { return info_; }
  [[nodiscard]] const std::vector<TrialIssue>& issues() const { return issues_; }
  [[nodiscard]] const std::vector<std::string>& warnings() const { return warnings_; }
  // The session's apparent truth, if the log carries one (simulated logs).
  [[nodiscard]] const std::optional<ApparentTruth>& apparent_truth() const { return apparent_; }
  [[nodiscard]] std::int64_t states_seen() const { return states_; }
  [[nodiscard]] std::int64_t cycle_gaps() const { return gaps_; }

 private:
  // A message held in the reorder window, keyed by (cycle, rank, arrival).
  struct Pending {
    std::int64_t cycle{0};
    int rank{0};
    std::uint64_t seq{0};
    bool twin{false};  // a state_t from the truth channel
    std::variant<manip::state_t, manip::trial_event_t, manip::impedance_truth_t> msg;
  };
  void hold(Pending&& p);
  void release_until(std::int64_t horizon_cycle);
  void process(const Pending& p);
  void do_state(const manip::state_t& msg);
  void do_trial_event(const manip::trial_event_t& msg);
  void do_truth_state(const manip::state_t& msg);
  void do_truth_impedance(const manip::impedance_truth_t& msg);
  void drop(const std::string& reason);

  TrialCallback cb_;
  SessionInfo info_;
  // info_.frame's rotation, evaluated once: it was a sin and a cos per
  // converted vector (9 per state message), 14 % of estimate_log's CPU time.
  Mat2 rot_{Mat2::Identity()};
  bool keep_unperturbed_signals_{true};
  bool keep_all_{true};  // of the current trial
  std::size_t last_size_{0};  // samples of the previous trial, to reserve the next one
  bool has_session_{false};
  bool in_trial_{false};
  bool bad_{false};
  std::string bad_reason_;
  TrialData cur_;
  std::int64_t last_cycle_{-1};  // cycle of the last state released
  std::int64_t states_{0};
  std::int64_t gaps_{0};
  std::vector<TrialIssue> issues_;
  std::vector<std::string> warnings_;
  std::optional<ApparentTruth> apparent_;
  // Reorder window.
  std::int64_t tolerance_{kDefaultReorderCycles};
  std::deque<Pending> pending_;
  std::uint64_t seq_{0};
  bool released_any_{false};
  std::int64_t released_cycle_{0};  // key of the last message released in order
  int released_rank_{0};
  std::int64_t latest_cycle_{0};  // cycle of the last state or twin to arrive (for the truth impedance)
};

}  // namespace manip::estimation
