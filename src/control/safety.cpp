#include "manip/control/safety.hpp"

#include <algorithm>
#include <cmath>

namespace manip::control {

SafetyMonitor::SafetyMonitor(const SafetyConfig& s, const CycleConfig& c, double sample_rate_hz)
    : s_(s),
      consecutive_limit_(c.overrun_fault_consecutive),
      per_second_limit_(c.overrun_fault_per_second),
      window_cycles_(std::llround(sample_rate_hz)),
      overrun_ring_(static_cast<std::size_t>(c.overrun_fault_per_second), 0) {}

void SafetyMonitor::reset_history() {
  have_seq_ = false;
  pos_same_ = force_same_ = 0;
  consecutive_ = 0;
  ring_head_ = ring_fill_ = 0;
}

std::uint32_t SafetyMonitor::check_inputs(const SensorReading& in, bool overran, bool logger_failed, FaultDetail& d) {
  std::uint32_t f = 0;
  ++cycle_;
  // NaN / Inf
  for (int i = 0; i < 2; ++i) {
    const double v[3] = {in.x_workspace_m[i], in.xd_workspace_mps[i], in.f_sensor_workspace_n[i]};
    for (double x : v)
      if (!std::isfinite(x)) {
        f |= fault::kSensorInvalid;
        d.set(fault::kSensorInvalid, i, x, 0.0);
      }
  }
  // stale samples
  if (have_seq_) {
    pos_same_ = in.position_seq == last_pos_seq_ ? pos_same_ + 1 : 0;
    force_same_ = in.force_seq == last_force_seq_ ? force_same_ + 1 : 0;
    if (pos_same_ >= s_.stale_cycles || force_same_ >= s_.stale_cycles) {
      f |= fault::kSensorStale;
      d.set(fault::kSensorStale, pos_same_ >= s_.stale_cycles ? 0 : 1, std::max(pos_same_, force_same_),
            s_.stale_cycles);
    }
  }
  have_seq_ = true;
  last_pos_seq_ = in.position_seq;
  last_force_seq_ = in.force_seq;
  if (!(f & fault::kSensorInvalid)) {
    for (int i = 0; i < 2; ++i) {
      const double x = in.x_workspace_m[i], v = in.xd_workspace_mps[i], fs = in.f_sensor_workspace_n[i];
      if (std::abs(x) > s_.workspace_limit_m) {
        f |= fault::kWorkspace;
        d.set(fault::kWorkspace, i, x, s_.workspace_limit_m);
      }
      if (std::abs(v) > s_.max_velocity_mps) {
        f |= fault::kVelocity;
        d.set(fault::kVelocity, i, v, s_.max_velocity_mps);
      }
      if (std::abs(fs) >= s_.sensor_saturation_n) {
        f |= fault::kSensorSaturated;
        d.set(fault::kSensorSaturated, i, fs, s_.sensor_saturation_n);
      }
      if (std::abs(fs) > s_.max_handle_force_n) {
        f |= fault::kHandleForce;
        d.set(fault::kHandleForce, i, fs, s_.max_handle_force_n);
      }
    }
  }
  if (in.status & (backend_status::kDriveFault | backend_status::kBackendError)) {
    f |= fault::kBackend;
    d.set(fault::kBackend, -1, static_cast<double>(in.status), 0.0);
  }
  if (in.status & backend_status::kHwEStopOpen) {
    f |= fault::kHardwareEStop;
    d.set(fault::kHardwareEStop, -1, static_cast<double>(in.status), 0.0);
  }
  // overrun policy: too many in a row, or too many within one second
  if (overran) {
    ++consecutive_;
    overrun_ring_[ring_head_] = cycle_;
    ring_head_ = (ring_head_ + 1) % overrun_ring_.size();
    ring_fill_ = std::min(ring_fill_ + 1, overrun_ring_.size());
    const std::int64_t oldest = overrun_ring_[ring_head_ % overrun_ring_.size()];
    const bool window_full = ring_fill_ == overrun_ring_.size() && cycle_ - oldest < window_cycles_;
    if (consecutive_ >= consecutive_limit_ || window_full) {
      f |= fault::kOverrun;
      d.set(fault::kOverrun, -1, consecutive_ >= consecutive_limit_ ? consecutive_ : per_second_limit_,
            consecutive_ >= consecutive_limit_ ? consecutive_limit_ : per_second_limit_);
    }
  } else {
    consecutive_ = 0;
  }
  if (logger_failed) {
    f |= fault::kLogger;
    d.set(fault::kLogger, -1, 0.0, 0.0);
  }
  return f;
}

std::uint32_t SafetyMonitor::check_outputs(const Vec2& f_motor_n, const Vec2& u_pert_n, const Vec2& x_ref_m,
                                           const Vec2& x_m, FaultDetail& d) const {
  std::uint32_t f = 0;
  for (int i = 0; i < 2; ++i) {
    if (!(std::abs(f_motor_n[i]) <= s_.max_motor_force_n)) {  // also catches NaN
      f |= fault::kMotorForce;
      d.set(fault::kMotorForce, i, f_motor_n[i], s_.max_motor_force_n);
    }
    if (!(std::abs(x_ref_m[i] - x_m[i]) <= s_.max_tracking_error_m)) {
      f |= fault::kTracking;
      d.set(fault::kTracking, i, x_ref_m[i] - x_m[i], s_.max_tracking_error_m);
    }
  }
  const double up = u_pert_n.norm();
  if (!(up <= s_.max_pert_amplitude_n)) {
    f |= fault::kPerturbation;
    d.set(fault::kPerturbation, -1, up, s_.max_pert_amplitude_n);
  }
  return f;
}

Vec2 SafetyMonitor::wall_force(const Vec2& x_ref_m, const Vec2& xd_ref_mps) const {
  Vec2 f = Vec2::Zero();
  for (int i = 0; i < 2; ++i) {
    const double pen = std::abs(x_ref_m[i]) - s_.wall_start_m;
    if (pen > 0.0) {
      const double sgn = x_ref_m[i] > 0 ? 1.0 : -1.0;
      f[i] = -sgn * s_.wall_stiffness_npm * pen - s_.wall_damping_nspm * xd_ref_mps[i];
    }
  }
  return f;
}

Vec2 SafetyMonitor::safe_force(const Vec2& xd_mps) const {
  if (s_.safe_law == SafeLaw::kZeroForce) return Vec2::Zero();
  Vec2 f = -s_.safe_damping_nspm * xd_mps;
  for (int i = 0; i < 2; ++i) {
    if (!std::isfinite(f[i])) f[i] = 0.0;  // a NaN velocity must not reach the drive
    f[i] = std::clamp(f[i], -s_.max_motor_force_n, s_.max_motor_force_n);
  }
  return f;
}

// ---------------------------------------------------------------------------

bool SafetyStateMachine::inputs_ok() {
  if (mode_ != Mode::kInit) return false;
  mode_ = Mode::kIdle;
  return true;
}

std::uint32_t SafetyStateMachine::raise(std::uint32_t bits) {
  const std::uint32_t fresh = bits & ~latched_;
  latched_ |= bits;
  if (bits && mode_ != Mode::kEStop && mode_ != Mode::kStopped) mode_ = Mode::kFault;
  return fresh;
}

void SafetyStateMachine::estop() {
  latched_ |= fault::kLcmEStop;
  if (mode_ != Mode::kStopped) mode_ = Mode::kEStop;
}

Reject SafetyStateMachine::fault_reset(std::uint32_t present) {
  if (mode_ != Mode::kFault && mode_ != Mode::kEStop) return Reject::kNotAllowedInMode;
  if (present) return Reject::kConditionPresent;
  latched_ = 0;
  mode_ = session_started_ ? Mode::kPaused : Mode::kIdle;
  return Reject::kNone;
}

Reject SafetyStateMachine::start_session() {
  if (mode_ == Mode::kDone) return Reject::kSessionDone;
  if (mode_ != Mode::kIdle) return session_started_ ? Reject::kSessionAlreadyStarted : Reject::kNotAllowedInMode;
  mode_ = Mode::kRunning;
  session_started_ = true;
  return Reject::kNone;
}

Reject SafetyStateMachine::pause() {
  if (mode_ != Mode::kRunning) return Reject::kNotAllowedInMode;
  mode_ = Mode::kPaused;
  return Reject::kNone;
}

Reject SafetyStateMachine::resume() {
  if (mode_ != Mode::kPaused) return Reject::kNotAllowedInMode;
  mode_ = Mode::kRunning;
  return Reject::kNone;
}

Reject SafetyStateMachine::stop_session() {
  if (mode_ == Mode::kDone) return Reject::kSessionDone;
  if (mode_ != Mode::kIdle && mode_ != Mode::kRunning && mode_ != Mode::kPaused) return Reject::kNotAllowedInMode;
  mode_ = Mode::kDone;
  return Reject::kNone;
}

void SafetyStateMachine::session_done() {
  if (mode_ == Mode::kRunning) mode_ = Mode::kDone;
}

void SafetyStateMachine::shutdown() { mode_ = Mode::kStopped; }

}  // namespace manip::control
