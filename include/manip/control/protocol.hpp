#pragma once
// The experiment protocol of paper §5.2, paced by the participant.
//
// Schedule: `movements` slots; `perturbed` of them (angles x repeats, or the
// first k of that multiset after shuffling when a session is shortened) are
// placed at uniformly random slots, their angles in random order; portable RNG
// seeded with protocol.seed, so a seed reproduces the schedule anywhere.
//
// Per trial (shoulder frame; "rest" = within target_radius and speed below
// rest_speed):
//   RETURN   between trials (trial = -1, perturbations off): START when the
//            handle has rested in the start target for start_hold_s.
//   REACH    trial running; the trigger is armed on perturbed trials.
//   PERTURBATION  T_pert from onset (ONSET event at the first crossing cycle).
//   GOAL_HOLD     resting in the goal; END after goal_hold_s (never during the
//            perturbation).
//   ABORT    after trial_timeout_s from START, or by the operator/a fault; an
//            aborted perturbed trial is re-queued at a random later position
//            (at most max_requeues times, then dropped and reported). An
//            aborted unperturbed slot is not repeated.
// With perturbations switched off, perturbed slots are deferred (the next
// unperturbed slot runs); if only perturbed slots remain, the phase is WAITING.
// The session is done when no slot remains. Allocation happens only in the
// constructor (the schedule is reserved for every possible re-queue).
#include <array>
#include <cstdint>
#include <vector>

#include "manip/common/perturbation.hpp"
#include "manip/control/config.hpp"
#include "manip/control/records.hpp"
#include "manip/common/rng.hpp"
#include "manip/control/trigger.hpp"

namespace manip::control {

struct TrialSpec {
  bool perturbed{false};
  double angle_rad{0.0};
  int requeues{0};
};

// The initial schedule for a configuration (deterministic per seed).
std::vector<TrialSpec> make_schedule(const ProtocolConfig& protocol, const PerturbationConfig& perturbation,
                                     int perturbed_count);
// The same from plain values (the simulator's session runner reuses it).
std::vector<TrialSpec> make_schedule(int movements, const std::vector<double>& angles_deg, int repeats_per_angle,
                                     int perturbed_count, std::uint64_t seed);

struct ProtocolEvents {
  std::array<TrialEventRecord, 4> ev{};
  int n{0};
  void clear() { n = 0; }
  void push(const TrialEventRecord& e) {
    if (n < static_cast<int>(ev.size())) ev[static_cast<std::size_t>(n++)] = e;
  }
};

class Protocol {
 public:
  explicit Protocol(const ControlConfig& cfg);

  // Session starts (or resumes): phase RETURN.
  void begin();
  // One cycle while the session runs. x/xd: measured handle, shoulder frame.
  // Events get cycle/utime from the arguments.
  void update(std::int64_t cycle, std::int64_t utime, const Vec2& x_sh, const Vec2& xd_sh, ProtocolEvents& out);
  // Operator/fault: abort the running trial if any (re-queue if perturbed); phase -> `after`.
  void abort_trial(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out);
  // Pause/fault: abort a running trial, phase NONE (resume with begin()).
  void suspend(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out);
  // STOP_SESSION: abort a running trial, phase DONE.
  void finish(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out);
  // NEXT_TRIAL between trials: start now if the handle is in the start target.
  Reject start_now(std::int64_t cycle, std::int64_t utime, const Vec2& x_sh, ProtocolEvents& out);
  void set_targets(const Vec2& start_sh, const Vec2& goal_sh);
  // PERTURBATIONS_ON/OFF; off aborts a perturbed trial whose onset has not happened.
  void set_perturbations_enabled(bool on, std::int64_t cycle, std::int64_t utime, ProtocolEvents& out);

  [[nodiscard]] Vec2 perturbation_force_shoulder_n() const { return u_pert_sh_; }
  [[nodiscard]] Phase phase() const { return phase_; }
  [[nodiscard]] std::int32_t trial_index() const { return trial_active_ ? trial_ : -1; }
  [[nodiscard]] bool trial_active() const { return trial_active_; }
  [[nodiscard]] bool done() const { return phase_ == Phase::kDone; }
  [[nodiscard]] bool perturbations_enabled() const { return pert_enabled_; }
  [[nodiscard]] const Vec2& start_shoulder_m() const { return start_; }
  [[nodiscard]] const Vec2& goal_shoulder_m() const { return goal_; }
  [[nodiscard]] const PerturbationTrigger& trigger() const { return trigger_; }
  [[nodiscard]] bool in_start(const Vec2& x_sh, const Vec2& xd_sh) const;
  [[nodiscard]] bool in_goal(const Vec2& x_sh, const Vec2& xd_sh) const;

  // Counters (read by the loop's owner thread; copied into the summary).
  struct Counters {
    int started{0}, completed{0}, aborted{0}, perturbed_completed{0}, onsets{0}, requeued{0}, dropped{0};
  };
  [[nodiscard]] const Counters& counters() const { return n_; }
  [[nodiscard]] int remaining() const { return static_cast<int>(schedule_.size()) - next_; }
  [[nodiscard]] const std::vector<TrialSpec>& schedule() const { return schedule_; }

 private:
  TrialEventRecord make_event(std::int8_t kind, std::int64_t cycle, std::int64_t utime) const;
  void start_trial(std::int64_t cycle, std::int64_t utime, ProtocolEvents& out);
  void end_trial_abort(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out);
  bool select_next();  // move the next runnable slot to next_; false if none

  ProtocolConfig p_;
  PerturbationProfile profile_;
  double fs_;
  Vec2 start_, goal_;
  std::int64_t start_hold_cycles_, goal_hold_cycles_, timeout_cycles_;
  std::vector<TrialSpec> schedule_;
  int next_{0};
  PortableRng requeue_rng_;
  PerturbationTrigger trigger_;
  bool pert_enabled_{true};

  Phase phase_{Phase::kNone};
  bool trial_active_{false};
  std::int32_t trial_{-1};
  std::int32_t next_trial_index_{0};
  TrialSpec current_{};
  std::int64_t trial_start_cycle_{0};
  std::int64_t hold_cycles_{0};
  Vec2 u_pert_sh_{Vec2::Zero()};
  Counters n_{};
};

}  // namespace manip::control
