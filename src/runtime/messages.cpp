#include "manip/runtime/messages.hpp"

#include <chrono>
#include <cstdio>


namespace manip::runtime {
using namespace manip::control;  // the loop's records and codes

manip::trial_event_t to_message(const TrialEventRecord& r) {
  manip::trial_event_t m{};
  m.utime = r.utime;
  m.cycle = r.cycle;
  m.trial = r.trial;
  m.kind = r.kind;
  m.perturbed = r.perturbed;
  for (int i = 0; i < 2; ++i) {
    m.start_shoulder_m[i] = r.start_shoulder_m[i];
    m.goal_shoulder_m[i] = r.goal_shoulder_m[i];
  }
  m.pert_angle_rad = r.pert_angle_rad;
  m.pert_amplitude_n = r.pert_amplitude_n;
  m.pert_duration_s = r.pert_duration_s;
  m.reason = abort_text(r.reason);
  if (r.dropped) m.reason += "; re-queue limit reached, perturbation dropped from the session";
  return m;
}

manip::command_status_t to_message(const CommandResultRecord& r) {
  manip::command_status_t m{};
  m.utime = r.utime;
  m.seq = r.seq;
  m.kind = r.kind;
  m.accepted = r.accepted;
  m.reason = reject_text(r.reason);
  if (r.reason == Reject::kNotAllowedInMode) m.reason += std::string(" (") + mode_name(r.mode_after) + ")";
  if (r.reason == Reject::kConditionPresent) m.reason += ": " + fault_names(r.detail);
  m.mode = static_cast<std::int8_t>(r.mode_after);
  return m;
}

manip::targets_t to_targets_message(const DisplayCue& cue, std::int64_t cycle, double target_radius_m,
                                    double trigger_x2_shoulder_m, std::int64_t command_seq) {
  manip::targets_t m{};
  m.utime = wall_clock_us();
  m.cycle = cycle;
  m.trial = cue.trial;
  m.phase = static_cast<std::int8_t>(cue.phase);
  for (int i = 0; i < 2; ++i) {
    m.start_shoulder_m[i] = cue.start_shoulder_m[i];
    m.goal_shoulder_m[i] = cue.goal_shoulder_m[i];
  }
  m.target_radius_m = target_radius_m;
  m.trigger_x2_shoulder_m = trigger_x2_shoulder_m;
  m.command_seq = command_seq;
  return m;
}

std::string fault_reason(const FaultRecord& r) {
  std::string s = fault_names(r.new_flags);
  const std::uint32_t first = r.new_flags & (~r.new_flags + 1);  // lowest bit
  char buf[200];
  switch (first) {
    case fault::kWorkspace:
    case fault::kVelocity:
    case fault::kHandleForce:
    case fault::kSensorSaturated:
    case fault::kMotorForce:
    case fault::kTracking:
      std::snprintf(buf, sizeof buf, ": axis %d value %.6g beyond limit %.6g (SI units)", r.axis, r.value, r.limit);
      s += buf;
      break;
    case fault::kPerturbation:
      std::snprintf(buf, sizeof buf, ": |u_pert| %.6g N beyond limit %.6g N", r.value, r.limit);
      s += buf;
      break;
    case fault::kSensorInvalid:
      std::snprintf(buf, sizeof buf, ": non-finite value on axis %d", r.axis);
      s += buf;
      break;
    case fault::kSensorStale:
      std::snprintf(buf, sizeof buf, ": %s sample unchanged for %.0f cycles (limit %.0f)", r.axis == 0 ? "position" : "force",
                    r.value, r.limit);
      s += buf;
      break;
    case fault::kOverrun:
      std::snprintf(buf, sizeof buf, ": %.0f overruns (limit %.0f)", r.value, r.limit);
      s += buf;
      break;
    case fault::kBackend:
    case fault::kHardwareEStop:
      std::snprintf(buf, sizeof buf, ": backend status 0x%x", static_cast<unsigned>(r.value));
      s += buf;
      break;
    case fault::kLcmEStop:
      s += ": advisory e-stop command received over LCM";
      break;
    case fault::kLogger:
      s += ": log writing failed";
      break;
    default:
      break;
  }
  return s;
}

std::int64_t wall_clock_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace manip::runtime
