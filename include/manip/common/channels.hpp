#pragma once
// LCM channel names are part of the schema (docs/schema.md).
namespace manip::channels {

inline constexpr const char* kSession = "MANIP_SESSION";          // session_t, first in every log
inline constexpr const char* kState = "MANIP_STATE";              // state_t, every cycle (logs)
inline constexpr const char* kStateLive = "MANIP_STATE_LIVE";     // state_t, decimated (live bus)
inline constexpr const char* kTrial = "MANIP_TRIAL";              // trial_event_t
inline constexpr const char* kCommand = "MANIP_COMMAND";          // command_t, from lab tools
inline constexpr const char* kCommandStatus = "MANIP_COMMAND_STATUS";  // command_status_t
inline constexpr const char* kHealth = "MANIP_HEALTH";            // health_t
inline constexpr const char* kFault = "MANIP_FAULT";              // fault_t
inline constexpr const char* kTargets = "MANIP_TARGETS";          // targets_t (live bus: display cue, on change + ~1 Hz)
inline constexpr const char* kDisplayHealth = "MANIP_DISPLAY_HEALTH";  // display_health_t (manipdisplay, ~1 Hz)
inline constexpr const char* kTruthState = "MANIP_TRUTH_STATE";   // state_t of the unperturbed twin (simulators)
inline constexpr const char* kTruthImpedance = "MANIP_TRUTH_IMPEDANCE";  // impedance_truth_t (simulators)
inline constexpr const char* kCanRaw = "MANIP_CAN_RAW";           // can_frames_t (can backend, record_raw_frames: true)

}  // namespace manip::channels
