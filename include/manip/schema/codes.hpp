#pragma once
// Codes carried by the controller's LCM messages (state_t.mode, state_t.phase,
// state_t.fault_flags, command_status_t.reason). The numbers are defined once,
// as `const`s in lcmtypes/state_t.lcm (so Python, MATLAB and Java clients get
// them from the generated types); this header gives them C++ types and names.
// Documented in docs/schema-controller.md; part of the schema (version 1).
#include <cstdint>
#include <string>

#include "manip/state_t.hpp"

namespace manip::schema {

// state_t.mode, health_t.mode, command_status_t.mode
enum class Mode : std::int8_t {
  kInit = manip::state_t::MODE_INIT,     // waiting for the first valid reading; motors disabled, zero force
  kIdle = manip::state_t::MODE_IDLE,     // admittance rendered, no session running
  kRunning = manip::state_t::MODE_RUNNING,  // admittance rendered, protocol running
  kPaused = manip::state_t::MODE_PAUSED,   // admittance rendered, protocol paused (operator)
  kFault = manip::state_t::MODE_FAULT,    // latched fault: safe law until FAULT_RESET
  kEStop = manip::state_t::MODE_ESTOP,    // advisory e-stop received over LCM: safe law until FAULT_RESET
  kDone = manip::state_t::MODE_DONE,     // session complete or stopped; admittance rendered, no trials
  kStopped = manip::state_t::MODE_STOPPED,  // shutting down: zero force, then drives disabled
};

// state_t.phase: where the protocol is (what the visual feedback shows).
enum class Phase : std::int8_t {
  kNone = manip::state_t::PHASE_NONE,          // no session activity (init, idle, paused, fault, e-stop, stopped)
  kReturn = manip::state_t::PHASE_RETURN,        // between trials: bring the handle to the start target and rest there
  kReach = manip::state_t::PHASE_REACH,         // trial running (go cue shown), no perturbation force
  kPerturbation = manip::state_t::PHASE_PERTURBATION,  // trial running, perturbation force active (T_pert after onset)
  kGoalHold = manip::state_t::PHASE_GOAL_HOLD,      // trial running, hand resting in the goal target
  kDone = manip::state_t::PHASE_DONE,          // all movements done (or session stopped)
  kWaiting = manip::state_t::PHASE_WAITING,       // between trials, but only perturbed trials remain and perturbations are off
};

// state_t.fault_flags / fault_t.fault_flags / health_t.fault_flags: latched bits.
namespace fault {
inline constexpr std::uint32_t kWorkspace = static_cast<std::uint32_t>(manip::state_t::FAULT_WORKSPACE);         // measured |x_i| beyond the workspace limit
inline constexpr std::uint32_t kVelocity = static_cast<std::uint32_t>(manip::state_t::FAULT_VELOCITY);          // measured |xd_i| beyond the velocity limit
inline constexpr std::uint32_t kHandleForce = static_cast<std::uint32_t>(manip::state_t::FAULT_HANDLE_FORCE);       // |f_sensor_i| beyond the handle-force limit
inline constexpr std::uint32_t kMotorForce = static_cast<std::uint32_t>(manip::state_t::FAULT_MOTOR_FORCE);        // computed motor force beyond the motor limit
inline constexpr std::uint32_t kPerturbation = static_cast<std::uint32_t>(manip::state_t::FAULT_PERTURBATION);      // perturbation force beyond its limit
inline constexpr std::uint32_t kSensorInvalid = static_cast<std::uint32_t>(manip::state_t::FAULT_SENSOR_INVALID);     // NaN or Inf in a reading
inline constexpr std::uint32_t kSensorStale = static_cast<std::uint32_t>(manip::state_t::FAULT_SENSOR_STALE);       // position or force sample not refreshed
inline constexpr std::uint32_t kSensorSaturated = static_cast<std::uint32_t>(manip::state_t::FAULT_SENSOR_SATURATED);   // force sensor at its range
inline constexpr std::uint32_t kBackend = static_cast<std::uint32_t>(manip::state_t::FAULT_BACKEND);           // backend/drive reports a fault
inline constexpr std::uint32_t kHardwareEStop = static_cast<std::uint32_t>(manip::state_t::FAULT_HARDWARE_ESTOP);     // hardware e-stop chain open / safe torque off
inline constexpr std::uint32_t kOverrun = static_cast<std::uint32_t>(manip::state_t::FAULT_OVERRUN);          // deadline overruns beyond the configured policy
inline constexpr std::uint32_t kLcmEStop = static_cast<std::uint32_t>(manip::state_t::FAULT_LCM_ESTOP);         // advisory e-stop command received over LCM
inline constexpr std::uint32_t kTracking = static_cast<std::uint32_t>(manip::state_t::FAULT_TRACKING);         // |x_ref - x| beyond the tracking limit
inline constexpr std::uint32_t kLogger = static_cast<std::uint32_t>(manip::state_t::FAULT_LOGGER);           // log writing failed (e.g. disk full)
inline constexpr std::uint32_t kCount = 14;
}  // namespace fault

// SensorReading::status bits reported by a backend.
namespace backend_status {
inline constexpr std::uint32_t kDrivesEnabled = 1u << 0;  // drives in "operation enabled"
inline constexpr std::uint32_t kDriveFault = 1u << 1;     // a drive reports a fault
inline constexpr std::uint32_t kHwEStopOpen = 1u << 2;    // e-stop chain open / STO active
inline constexpr std::uint32_t kBackendError = 1u << 3;   // communication error (bus, timeout)
}  // namespace backend_status

// Why a command was rejected (command_status_t.reason carries the text).
enum class Reject : std::int8_t {
  kNone = 0,
  kUnknownKind,
  kUndecodable,
  kNotFinite,
  kOutOfWorkspace,
  kTargetsTooClose,
  kTriggerNotBetweenTargets,
  kQueueFull,
  kNotAllowedInMode,
  kSessionAlreadyStarted,
  kSessionDone,
  kTrialActive,
  kHandNotInStart,
  kConditionPresent,
};

// trial_event_t.reason for ABORT (text) and internal code.
enum class AbortReason : std::int8_t {
  kNone = 0,
  kTimeout,
  kFault,
  kPaused,
  kOperatorNext,
  kPerturbationsOff,
  kStopped,
  kShutdown,
};

// Why the controller entered kStopped.
enum class StopReason : std::int8_t {
  kNone = 0,
  kSessionDone,   // all movements done, or STOP_SESSION
  kDuration,      // --duration reached
  kRequested,     // signal / supervisor
  kFault,         // fault with stop_on_fault
  kLogger,        // log writing failed
};

const char* mode_name(Mode m);
const char* phase_name(Phase p);
const char* fault_bit_name(std::uint32_t bit);  // single bit
std::string fault_names(std::uint32_t flags);   // "workspace|velocity"
const char* reject_text(Reject r);
const char* abort_text(AbortReason r);
const char* stop_reason_name(StopReason r);
const char* command_kind_name(std::int8_t kind);

}  // namespace manip::schema

// The control law speaks these codes; spelled control::Mode etc. there.
namespace manip::control {
using schema::AbortReason;
using schema::Mode;
using schema::Phase;
using schema::Reject;
using schema::StopReason;
namespace fault = schema::fault;
namespace backend_status = schema::backend_status;
using schema::abort_text;
using schema::command_kind_name;
using schema::fault_bit_name;
using schema::fault_names;
using schema::mode_name;
using schema::phase_name;
using schema::reject_text;
using schema::stop_reason_name;
}  // namespace manip::control
