#include "manip/control/controller.hpp"

#include <algorithm>
#include <cmath>

#include "manip/command_t.hpp"
#include "manip/trial_event_t.hpp"

namespace manip::control {
namespace {
constexpr auto kRelaxed = std::memory_order_relaxed;

void copy2(double* dst, const Vec2& v) {
  dst[0] = v[0];
  dst[1] = v[1];
}
bool finite2(const Vec2& v) { return std::isfinite(v[0]) && std::isfinite(v[1]); }
}  // namespace

Controller::Controller(const ControlConfig& cfg, ControllerQueues queues, const ControllerOptions& opt)
    : cfg_(cfg),
      q_(queues),
      opt_(opt),
      period_us_(std::llround(1e6 / cfg.session.sample_rate_hz)),
      drive_decimation_(std::max(1, cfg.drive_decimation())),
      bus_decimation_(
          std::max(1, static_cast<int>(std::lround(cfg.session.sample_rate_hz / cfg.cycle.live_state_rate_hz)))),
      frame_(cfg.session.frame),
      adm_(cfg.session.m_adm_kg, cfg.session.d_adm_nspm, cfg.dt_s()),
      pd_{cfg.pd.kp_npm, cfg.pd.kd_nspm, cfg.pd.ff_mass_kg, cfg.pd.ff_viscous_nspm, cfg.pd.ff_sensor_force_gain},
      monitor_(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz),
      protocol_(cfg) {}

void Controller::request_stop(StopReason why) {
  std::int8_t expected = 0;
  stop_request_.compare_exchange_strong(expected, static_cast<std::int8_t>(why));
}

void Controller::push_record(const LoopRecord& r, bool to_bus) {
  if (q_.log && !q_.log->try_push(r)) status_.log_drops.store(status_.log_drops.load(kRelaxed) + 1, kRelaxed);
  if (to_bus && q_.bus && !q_.bus->try_push(r))
    status_.bus_drops.store(status_.bus_drops.load(kRelaxed) + 1, kRelaxed);
}

void Controller::enter_stopped(StopReason why) {
  if (sm_.mode() == Mode::kStopped) return;
  protocol_.finish(cycle_, utime_,
                   why == StopReason::kFault || why == StopReason::kLogger ? AbortReason::kFault : AbortReason::kShutdown,
                   events_);
  sm_.shutdown();
  stopped_cycles_ = 0;
  status_.stop_reason.store(static_cast<std::int8_t>(why), kRelaxed);
}

void Controller::raise_faults(std::uint32_t bits, const FaultDetail& d) {
  const Mode before = sm_.mode();
  const std::uint32_t fresh = sm_.raise(bits);
  if (!fresh) return;
  if (before != Mode::kFault && before != Mode::kEStop && before != Mode::kStopped)
    protocol_.suspend(cycle_, utime_, AbortReason::kFault, events_);
  if (have_pending_fault_) {
    pending_fault_.new_flags |= fresh;
  } else {
    pending_fault_ = FaultRecord{utime_, cycle_, fresh, 0u, Mode::kFault, d.axis, d.value, d.limit};
    have_pending_fault_ = true;
  }
  if (bits & fault::kLogger)
    enter_stopped(StopReason::kLogger);
  else if (opt_.stop_on_fault)
    enter_stopped(StopReason::kFault);
}

void Controller::handle_command(const Command& c, const SensorReading& in) {
  Reject r = Reject::kNone;
  std::uint32_t detail = 0;
  const Mode m = sm_.mode();
  switch (c.kind) {
    case manip::command_t::START_SESSION:
      r = sm_.start_session();
      if (r == Reject::kNone) protocol_.begin();
      break;
    case manip::command_t::PAUSE:
      r = sm_.pause();
      if (r == Reject::kNone) protocol_.suspend(cycle_, utime_, AbortReason::kPaused, events_);
      break;
    case manip::command_t::RESUME:
      r = sm_.resume();
      if (r == Reject::kNone) protocol_.begin();
      break;
    case manip::command_t::STOP_SESSION:
      r = sm_.stop_session();
      if (r == Reject::kNone) protocol_.finish(cycle_, utime_, AbortReason::kStopped, events_);
      break;
    case manip::command_t::NEXT_TRIAL:
      if (m != Mode::kRunning) {
        r = Reject::kNotAllowedInMode;
      } else if (protocol_.trial_active()) {
        protocol_.abort_trial(cycle_, utime_, AbortReason::kOperatorNext, events_);
      } else if (!finite2(in.x_workspace_m)) {
        r = Reject::kHandNotInStart;
      } else {
        r = protocol_.start_now(cycle_, utime_, frame_.point_to_shoulder(in.x_workspace_m), events_);
      }
      break;
    case manip::command_t::SET_TARGETS:
      if (m == Mode::kIdle || m == Mode::kPaused || (m == Mode::kRunning && !protocol_.trial_active()))
        protocol_.set_targets(c.start_shoulder_m, c.goal_shoulder_m);
      else
        r = m == Mode::kRunning ? Reject::kTrialActive : Reject::kNotAllowedInMode;
      break;
    case manip::command_t::PERTURBATIONS_ON:
    case manip::command_t::PERTURBATIONS_OFF:
      if (m == Mode::kIdle || m == Mode::kRunning || m == Mode::kPaused || m == Mode::kDone)
        protocol_.set_perturbations_enabled(c.kind == manip::command_t::PERTURBATIONS_ON, cycle_, utime_, events_);
      else
        r = Reject::kNotAllowedInMode;
      break;
    case manip::command_t::ESTOP: {
      const bool was_latched = sm_.latched() & fault::kLcmEStop;
      if (m != Mode::kFault && m != Mode::kEStop && m != Mode::kStopped)
        protocol_.suspend(cycle_, utime_, AbortReason::kFault, events_);
      sm_.estop();
      if (!was_latched && !have_pending_fault_) {
        pending_fault_ = FaultRecord{utime_, cycle_, fault::kLcmEStop, 0u, sm_.mode(), -1, 0.0, 0.0};
        have_pending_fault_ = true;
      }
      if (opt_.stop_on_fault) enter_stopped(StopReason::kFault);
      break;
    }
    case manip::command_t::FAULT_RESET:
      r = sm_.fault_reset(present_);
      if (r == Reject::kConditionPresent) detail = present_;
      if (r == Reject::kNone) {
        monitor_.reset_history();
        if (finite2(in.x_workspace_m)) adm_.reset(in.x_workspace_m);
      }
      break;
    default:
      r = Reject::kUnknownKind;  // the bus thread filters these; defensive
      break;
  }
  CommandResultRecord res{utime_, c.seq, c.kind, r == Reject::kNone, r, sm_.mode(), detail};
  auto& counter = r == Reject::kNone ? status_.commands_accepted : status_.commands_rejected;
  counter.store(counter.load(kRelaxed) + 1, kRelaxed);
  push_record(LoopRecord(res), true);
}

const ActuatorCommand& Controller::step(const SensorReading& in, std::int64_t cycle, bool overran) {
  cycle_ = cycle;
  utime_ = utime_of(cycle);
  events_.clear();
  have_pending_fault_ = false;
  const bool safe_before = sm_.safe_law();

  // 1. commands (bounded per cycle: a flood cannot stretch the cycle)
  if (q_.commands) {
    Command c;
    for (int i = 0; i < cfg_.cycle.max_commands_per_cycle && q_.commands->try_pop(c); ++i) handle_command(c, in);
  }

  // 2. orderly stop
  if (const auto req = stop_request_.load(kRelaxed); req != 0 && sm_.mode() != Mode::kStopped)
    enter_stopped(static_cast<StopReason>(req));
  if (opt_.max_cycles > 0 && cycle >= opt_.max_cycles && sm_.mode() != Mode::kStopped)
    enter_stopped(StopReason::kDuration);

  // 3. safety checks of the inputs
  FaultDetail det;
  const bool logger_failed = logger_failed_ && logger_failed_->load(kRelaxed);
  present_ = monitor_.check_inputs(in, overran, logger_failed, det);
  if (present_) raise_faults(present_, det);
  if (sm_.mode() == Mode::kInit && !present_) {
    sm_.inputs_ok();
    adm_.reset(in.x_workspace_m);
    if (cfg_.protocol.autostart && sm_.start_session() == Reject::kNone) protocol_.begin();
  }

  // 4-5. protocol, admittance, PD
  Vec2 f_cmd = Vec2::Zero();
  Vec2 u_pert_w = Vec2::Zero();
  if (!sm_.safe_law()) {
    if (sm_.mode() == Mode::kRunning) {
      const Vec2 x_sh = frame_.point_to_shoulder(in.x_workspace_m);
      const Vec2 xd_sh = frame_.vector_to_shoulder(in.xd_workspace_mps);
      protocol_.update(cycle, utime_, x_sh, xd_sh, events_);
      u_pert_w = frame_.vector_to_workspace(protocol_.perturbation_force_shoulder_n());
      if (protocol_.done()) sm_.session_done();
    }
    const Vec2 f_adm = in.f_sensor_workspace_n + u_pert_w + monitor_.wall_force(adm_.x(), adm_.xd());
    adm_.step(f_adm);
    f_cmd = pd_force(pd_, adm_.x(), adm_.xd(), adm_.xdd(), in.x_workspace_m, in.xd_workspace_mps,
                     in.f_sensor_workspace_n);
    FaultDetail d2;
    if (const std::uint32_t out = monitor_.check_outputs(f_cmd, u_pert_w, adm_.x(), in.x_workspace_m, d2))
      raise_faults(out, d2);
  }
  if (sm_.mode() == Mode::kDone && opt_.stop_when_done) enter_stopped(StopReason::kSessionDone);

  // 6. safe law, in the same cycle as the fault
  if (sm_.safe_law()) {
    u_pert_w.setZero();
    const Mode m = sm_.mode();
    f_cmd = (m == Mode::kInit || m == Mode::kStopped) ? Vec2::Zero() : monitor_.safe_force(in.xd_workspace_mps);
    if (finite2(in.x_workspace_m)) adm_.reset(in.x_workspace_m);
  }
  if (sm_.mode() == Mode::kStopped && ++stopped_cycles_ >= cfg_.safety.shutdown_cycles)
    status_.finished.store(true, std::memory_order_release);

  // 7. drive decimation; a change to or from the safe law goes out at once
  const bool safe_now = sm_.safe_law();
  const bool tick = (cycle % drive_decimation_ == 0) || (safe_now != safe_before);
  if (tick) held_force_ = f_cmd;
  cmd_.f_motor_n = held_force_;
  cmd_.send = tick;
  cmd_.enable = sm_.mode() != Mode::kInit;
  const Mode m = sm_.mode();
  // States from the START cycle to the END/ABORT cycle inclusive carry the trial index.
  std::int32_t trial = protocol_.trial_index();
  for (int i = 0; i < events_.n; ++i) {
    const auto& e = events_.ev[static_cast<std::size_t>(i)];
    if (e.kind == manip::trial_event_t::END || e.kind == manip::trial_event_t::ABORT) trial = e.trial;
  }
  const Phase phase = m == Mode::kRunning ? protocol_.phase() : (m == Mode::kDone ? Phase::kDone : Phase::kNone);
  cmd_.cue.phase = phase;
  cmd_.cue.trial = trial;
  cmd_.cue.start_shoulder_m = protocol_.start_shoulder_m();
  cmd_.cue.goal_shoulder_m = protocol_.goal_shoulder_m();

  // state and events
  state_.cycle = cycle;
  state_.utime = utime_;
  state_.trial = trial;
  state_.phase = static_cast<std::int8_t>(phase);
  copy2(state_.x_workspace_m, in.x_workspace_m);
  copy2(state_.xd_workspace_mps, in.xd_workspace_mps);
  copy2(state_.x_ref_workspace_m, adm_.x());
  copy2(state_.xd_ref_workspace_mps, adm_.xd());
  copy2(state_.xdd_ref_workspace_mps2, adm_.xdd());
  copy2(state_.f_sensor_workspace_n, in.f_sensor_workspace_n);
  copy2(state_.u_pert_workspace_n, u_pert_w);
  copy2(state_.f_motor_n, held_force_);
  state_.mode = static_cast<std::int8_t>(m);
  state_.fault_flags = static_cast<std::int32_t>(sm_.latched());
  // Order in the queues (and the log): command results, trial events of this
  // cycle, the state, then a fault record (whose history ends with this state).
  for (int i = 0; i < events_.n; ++i) push_record(LoopRecord(events_.ev[static_cast<std::size_t>(i)]), true);
  push_record(LoopRecord(state_), cycle % bus_decimation_ == 0);
  if (have_pending_fault_) {
    pending_fault_.fault_flags = sm_.latched();
    pending_fault_.mode = m;
    push_record(LoopRecord(pending_fault_), true);
  }

  status_.cycle.store(cycle, kRelaxed);
  status_.mode.store(static_cast<std::int8_t>(m), kRelaxed);
  status_.phase.store(static_cast<std::int8_t>(phase), kRelaxed);
  status_.fault_flags.store(sm_.latched(), kRelaxed);
  status_.trial.store(state_.trial, kRelaxed);
  return cmd_;
}

}  // namespace manip::control
