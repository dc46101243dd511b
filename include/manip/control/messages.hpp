#pragma once
// Conversions from the loop's fixed-size records to LCM messages (non-real-time
// threads only: these build strings), and the session message.
#include <string>

#include "manip/command_status_t.hpp"
#include "manip/control/config.hpp"
#include "manip/control/records.hpp"
#include "manip/session_t.hpp"
#include "manip/trial_event_t.hpp"

namespace manip::control {

manip::trial_event_t to_message(const TrialEventRecord& r);
manip::command_status_t to_message(const CommandResultRecord& r);
// "workspace: axis 0 value 0.1512 (limit 0.147)" etc.
std::string fault_reason(const FaultRecord& r);

// Every session_t field from the configuration. source: "manip_rt/sim", ...
manip::session_t make_session_message(const RtConfig& cfg, const std::string& source, std::int64_t utime_start_us);

// Wall clock now [us since the Unix epoch].
std::int64_t wall_clock_us();

}  // namespace manip::control
