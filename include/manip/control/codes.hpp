#pragma once
// Codes carried by the controller's LCM messages (state_t.mode, state_t.phase,
// state_t.fault_flags, command_status_t.reason). Documented in
// docs/schema-controller.md; values are part of the schema (version 1).
#include <cstdint>
#include <string>

namespace manip::control {

// state_t.mode, health_t.mode, command_status_t.mode
enum class Mode : std::int8_t {
  kInit = 0,     // waiting for the first valid reading; motors disabled, zero force
  kIdle = 1,     // admittance rendered, no session running
  kRunning = 2,  // admittance rendered, protocol running
  kPaused = 3,   // admittance rendered, protocol paused (operator)
  kFault = 4,    // latched fault: safe law until FAULT_RESET
  kEStop = 5,    // advisory e-stop received over LCM: safe law until FAULT_RESET
  kDone = 6,     // session complete or stopped; admittance rendered, no trials
  kStopped = 7,  // shutting down: zero force, then drives disabled
};

// state_t.phase: where the protocol is (what the visual feedback shows).
enum class Phase : std::int8_t {
  kNone = 0,          // no session activity (init, idle, paused, fault, e-stop, stopped)
  kReturn = 1,        // between trials: bring the handle to the start target and rest there
  kReach = 2,         // trial running (go cue shown), no perturbation force
  kPerturbation = 3,  // trial running, perturbation force active (T_pert after onset)
  kGoalHold = 4,      // trial running, hand resting in the goal target
  kDone = 5,          // all movements done (or session stopped)
  kWaiting = 6,       // between trials, but only perturbed trials remain and perturbations are off
};

// state_t.fault_flags / fault_t.fault_flags / health_t.fault_flags: latched bits.
namespace fault {
inline constexpr std::uint32_t kWorkspace = 1u << 0;         // measured |x_i| beyond the workspace limit
inline constexpr std::uint32_t kVelocity = 1u << 1;          // measured |xd_i| beyond the velocity limit
inline constexpr std::uint32_t kHandleForce = 1u << 2;       // |f_sensor_i| beyond the handle-force limit
inline constexpr std::uint32_t kMotorForce = 1u << 3;        // computed motor force beyond the motor limit
inline constexpr std::uint32_t kPerturbation = 1u << 4;      // perturbation force beyond its limit
inline constexpr std::uint32_t kSensorInvalid = 1u << 5;     // NaN or Inf in a reading
inline constexpr std::uint32_t kSensorStale = 1u << 6;       // position or force sample not refreshed
inline constexpr std::uint32_t kSensorSaturated = 1u << 7;   // force sensor at its range
inline constexpr std::uint32_t kBackend = 1u << 8;           // backend/drive reports a fault
inline constexpr std::uint32_t kHardwareEStop = 1u << 9;     // hardware e-stop chain open / safe torque off
inline constexpr std::uint32_t kOverrun = 1u << 10;          // deadline overruns beyond the configured policy
inline constexpr std::uint32_t kLcmEStop = 1u << 11;         // advisory e-stop command received over LCM
inline constexpr std::uint32_t kTracking = 1u << 12;         // |x_ref - x| beyond the tracking limit
inline constexpr std::uint32_t kLogger = 1u << 13;           // log writing failed (e.g. disk full)
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

}  // namespace manip::control
