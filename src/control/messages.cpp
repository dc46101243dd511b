#include "manip/control/messages.hpp"

#include <chrono>
#include <cstdio>

#include "manip/version.hpp"

namespace manip::control {

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

manip::session_t make_session_message(const RtConfig& cfg, const std::string& source, std::int64_t utime_start_us) {
  manip::session_t s{};
  s.schema_version = manip::session_t::SCHEMA_VERSION;
  s.software_version = manip::kVersion;
  s.source = source;
  s.utime_start = utime_start_us;
  s.participant_id = cfg.participant.participant_id;
  s.session_id = cfg.participant.session_id;
  s.sample_rate_hz = cfg.loop.sample_rate_hz;
  s.drive_rate_hz = cfg.loop.drive_rate_hz;
  for (int i = 0; i < 2; ++i) {
    s.m_adm_kg[i] = cfg.admittance.m_adm_kg[i];
    s.d_adm_nspm[i] = cfg.admittance.d_adm_nspm[i];
    s.m_handle_kg[i] = cfg.handle_mass_kg[i];
    s.workspace_origin_in_shoulder_m[i] = cfg.frames.origin_in_shoulder_m[i];
    s.segment_length_m[i] = cfg.participant.segment_length_m[i];
    s.segment_mass_kg[i] = cfg.participant.segment_mass_kg[i];
    s.segment_com_m[i] = cfg.participant.segment_com_m[i];
    s.segment_inertia_kgm2[i] = cfg.participant.segment_inertia_kgm2[i];
  }
  s.workspace_to_shoulder_rot_rad = cfg.frames.rot_rad;
  s.body_mass_kg = cfg.participant.body_mass_kg;
  s.body_height_m = cfg.participant.body_height_m;
  s.pert_duration_s = cfg.perturbation.duration_s;
  s.pert_amplitude_n = cfg.perturbation.amplitude_n;
  s.trigger_x2_shoulder_m = cfg.perturbation.trigger_x2_shoulder_m;
  s.config_yaml = cfg.effective_yaml;
  return s;
}

}  // namespace manip::control
