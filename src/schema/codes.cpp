#include "manip/schema/codes.hpp"

#include "manip/command_t.hpp"

namespace manip::schema {

const char* mode_name(Mode m) {
  switch (m) {
    case Mode::kInit: return "INIT";
    case Mode::kIdle: return "IDLE";
    case Mode::kRunning: return "RUNNING";
    case Mode::kPaused: return "PAUSED";
    case Mode::kFault: return "FAULT";
    case Mode::kEStop: return "ESTOP";
    case Mode::kDone: return "DONE";
    case Mode::kStopped: return "STOPPED";
  }
  return "?";
}

const char* phase_name(Phase p) {
  switch (p) {
    case Phase::kNone: return "NONE";
    case Phase::kReturn: return "RETURN";
    case Phase::kReach: return "REACH";
    case Phase::kPerturbation: return "PERTURBATION";
    case Phase::kGoalHold: return "GOAL_HOLD";
    case Phase::kDone: return "DONE";
    case Phase::kWaiting: return "WAITING";
  }
  return "?";
}

const char* fault_bit_name(std::uint32_t bit) {
  switch (bit) {
    case fault::kWorkspace: return "workspace";
    case fault::kVelocity: return "velocity";
    case fault::kHandleForce: return "handle_force";
    case fault::kMotorForce: return "motor_force";
    case fault::kPerturbation: return "perturbation";
    case fault::kSensorInvalid: return "sensor_invalid";
    case fault::kSensorStale: return "sensor_stale";
    case fault::kSensorSaturated: return "sensor_saturated";
    case fault::kBackend: return "backend";
    case fault::kHardwareEStop: return "hardware_estop";
    case fault::kOverrun: return "overrun";
    case fault::kLcmEStop: return "lcm_estop";
    case fault::kTracking: return "tracking";
    case fault::kLogger: return "logger";
    default: return "unknown";
  }
}

std::string fault_names(std::uint32_t flags) {
  std::string s;
  for (std::uint32_t i = 0; i < 32; ++i) {
    const std::uint32_t b = 1u << i;
    if (!(flags & b)) continue;
    if (!s.empty()) s += '|';
    s += fault_bit_name(b);
  }
  return s.empty() ? "none" : s;
}

const char* reject_text(Reject r) {
  switch (r) {
    case Reject::kNone: return "";
    case Reject::kUnknownKind: return "unknown command kind";
    case Reject::kUndecodable: return "undecodable command_t payload";
    case Reject::kNotFinite: return "target coordinates must be finite numbers [m]";
    case Reject::kOutOfWorkspace: return "target outside the workspace walls";
    case Reject::kTargetsTooClose: return "start and goal targets closer than two target radii";
    case Reject::kTriggerNotBetweenTargets: return "perturbation trigger x2 not strictly between start and goal x2";
    case Reject::kQueueFull: return "command queue full (command flood); try again";
    case Reject::kNotAllowedInMode: return "not allowed in the current mode";
    case Reject::kSessionAlreadyStarted: return "session already started";
    case Reject::kSessionDone: return "session already complete";
    case Reject::kTrialActive: return "not allowed while a trial is running";
    case Reject::kHandNotInStart: return "handle not in the start target";
    case Reject::kConditionPresent: return "fault condition still present";
  }
  return "?";
}

const char* abort_text(AbortReason r) {
  switch (r) {
    case AbortReason::kNone: return "";
    case AbortReason::kTimeout: return "timeout";
    case AbortReason::kFault: return "fault";
    case AbortReason::kPaused: return "paused by operator";
    case AbortReason::kOperatorNext: return "operator: next trial";
    case AbortReason::kPerturbationsOff: return "perturbations switched off before onset";
    case AbortReason::kStopped: return "session stopped";
    case AbortReason::kShutdown: return "controller shutdown";
  }
  return "?";
}

const char* stop_reason_name(StopReason r) {
  switch (r) {
    case StopReason::kNone: return "none";
    case StopReason::kSessionDone: return "session done";
    case StopReason::kDuration: return "duration reached";
    case StopReason::kRequested: return "stop requested";
    case StopReason::kFault: return "fault";
    case StopReason::kLogger: return "log failure";
  }
  return "?";
}

const char* command_kind_name(std::int8_t kind) {
  switch (kind) {
    case manip::command_t::START_SESSION: return "START_SESSION";
    case manip::command_t::PAUSE: return "PAUSE";
    case manip::command_t::RESUME: return "RESUME";
    case manip::command_t::STOP_SESSION: return "STOP_SESSION";
    case manip::command_t::NEXT_TRIAL: return "NEXT_TRIAL";
    case manip::command_t::SET_TARGETS: return "SET_TARGETS";
    case manip::command_t::PERTURBATIONS_ON: return "PERTURBATIONS_ON";
    case manip::command_t::PERTURBATIONS_OFF: return "PERTURBATIONS_OFF";
    case manip::command_t::ESTOP: return "ESTOP";
    case manip::command_t::FAULT_RESET: return "FAULT_RESET";
    default: return "UNKNOWN";
  }
}

}  // namespace manip::schema
