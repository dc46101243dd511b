#pragma once
// Helpers for the control tests: the built-in default configuration (= the
// shipped config/rt.yaml), a queue drain, and scripted readings.
#include <cmath>
#include <string>
#include <vector>

#include "manip/runtime/config.hpp"
#include "manip/control/controller.hpp"
#include "manip/control/records.hpp"
#include "manip/runtime/spsc_queue.hpp"

namespace test_support {

inline std::string shipped_config_path() { return std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml"; }

inline manip::runtime::RtConfig shipped_config(const manip::runtime::ConfigOverrides& ov = {}) {
  return manip::runtime::load_rt_config(shipped_config_path(), ov);
}

struct Drained {
  std::vector<manip::state_t> states;
  std::vector<manip::control::TrialEventRecord> events;
  std::vector<manip::control::FaultRecord> faults;
  std::vector<manip::control::CommandResultRecord> results;
};

inline void drain(manip::runtime::RecordQueue& q, Drained& d) {
  manip::control::LoopRecord r;
  while (q.try_pop(r)) {
    if (auto* s = std::get_if<manip::state_t>(&r)) d.states.push_back(*s);
    if (auto* e = std::get_if<manip::control::TrialEventRecord>(&r)) d.events.push_back(*e);
    if (auto* f = std::get_if<manip::control::FaultRecord>(&r)) d.faults.push_back(*f);
    if (auto* c = std::get_if<manip::control::CommandResultRecord>(&r)) d.results.push_back(*c);
  }
}

// Scripted readings do not follow the admittance reference: switch off the
// output checks that compare the two (tracking error, motor force).
inline manip::runtime::ConfigOverrides scripted(manip::runtime::ConfigOverrides ov) {
  ov.emplace_back("safety.max_tracking_error_m", "10.0");
  ov.emplace_back("safety.max_motor_force_n", "1.0e12");
  return ov;
}

// A valid reading at workspace position x, velocity xd, sensor force f; seq = cycle+1.
inline manip::control::SensorReading reading(std::int64_t cycle, const manip::Vec2& x,
                                             const manip::Vec2& xd = manip::Vec2::Zero(),
                                             const manip::Vec2& f = manip::Vec2::Zero()) {
  manip::control::SensorReading r;
  r.x_workspace_m = x;
  r.xd_workspace_mps = xd;
  r.f_sensor_workspace_n = f;
  r.position_seq = r.force_seq = static_cast<std::uint64_t>(cycle + 1);
  r.status = manip::control::backend_status::kDrivesEnabled;
  return r;
}

}  // namespace test_support
