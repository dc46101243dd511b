#pragma once
// Conversions from the loop's fixed-size records to LCM messages (non-real-time
// threads only: these build strings). The session message is
// schema::to_message(SessionDescription).
#include <string>

#include "manip/command_status_t.hpp"
#include "manip/control/records.hpp"
#include "manip/session_t.hpp"
#include "manip/targets_t.hpp"
#include "manip/trial_event_t.hpp"

namespace manip::runtime {

manip::trial_event_t to_message(const control::TrialEventRecord& r);
manip::command_status_t to_message(const control::CommandResultRecord& r);
// MANIP_TARGETS for the participant's display: the cue plus the fixed geometry.
manip::targets_t to_targets_message(const control::DisplayCue& cue, std::int64_t cycle, double target_radius_m,
                                    double trigger_x2_shoulder_m, std::int64_t command_seq);
// "workspace: axis 0 value 0.1512 (limit 0.147)" etc.
std::string fault_reason(const control::FaultRecord& r);

// Wall clock now [us since the Unix epoch].
std::int64_t wall_clock_us();

}  // namespace manip::runtime
