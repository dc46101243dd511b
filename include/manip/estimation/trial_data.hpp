#pragma once
// A session as the estimator sees it: the session message reduced to what the
// method needs, and each trial's samples from its START to its END event,
// converted once from the workspace frame of the log to the shoulder frame of
// the arm (common/frames.hpp).
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
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

// A trial that could not be used, and why (reported, never silently dropped).
struct TrialIssue {
  int trial{-1};
  std::string reason;
};

// Builds trials from a message stream and hands each complete trial to a
// callback as soon as its END arrives, so a session of any length is
// processed in bounded memory. Checks: session message first, gapless cycle
// counter within a trial, finite samples, onset inside the trial.
class TrialAssembler final : public logging::SessionHandler {
 public:
  using TrialCallback = std::function<void(const SessionInfo&, TrialData&&)>;
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

  // Call after the stream ended: reports a trial left open.
  void finish();

  [[nodiscard]] bool has_session() const { return has_session_; }
  [[nodiscard]] const SessionInfo& session() const { return info_; }
  [[nodiscard]] const std::vector<TrialIssue>& issues() const { return issues_; }
  [[nodiscard]] const std::vector<std::string>& warnings() const { return warnings_; }
  [[nodiscard]] std::int64_t states_seen() const { return states_; }
  [[nodiscard]] std::int64_t cycle_gaps() const { return gaps_; }

 private:
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
  bool warned_no_session_{false};
  bool in_trial_{false};
  bool bad_{false};
  std::string bad_reason_;
  TrialData cur_;
  std::int64_t last_cycle_{-1};
  std::int64_t states_{0};
  std::int64_t gaps_{0};
  std::vector<TrialIssue> issues_;
  std::vector<std::string> warnings_;
  // Truth arrives after the trial's states; keep the last handed-over trial's
  // truth? No: the runner emits twin + truth before END, so both are in cur_.
};

}  // namespace manip::estimation
