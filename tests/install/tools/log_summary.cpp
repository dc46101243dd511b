// The C++ reader's view of a log, as "key value" lines, for tests/install's
// Java check (ReadLog.java prints the same keys through manip-lcmtypes.jar).
// Reads with manip::logging::read_log, the reader every manip tool uses.
#include <cstdint>
#include <iostream>

#include "manip/logging/session_stream.hpp"

namespace {
struct Summary final : manip::logging::SessionHandler {
  double sample_rate_hz = 0;
  std::int32_t schema_version = 0;
  std::string source;
  std::int64_t states = 0, perturbation_states = 0, onsets = 0, last_cycle = -1;
  void on_session(const manip::session_t& m) override {
    sample_rate_hz = m.sample_rate_hz;
    schema_version = m.schema_version;
    source = m.source;
  }
  void on_state(const manip::state_t& m) override {
    ++states;
    if (m.phase == manip::state_t::PHASE_PERTURBATION) ++perturbation_states;
    last_cycle = m.cycle;
  }
  void on_trial_event(const manip::trial_event_t& m) override {
    if (m.kind == manip::trial_event_t::ONSET) ++onsets;
  }
};
}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: log_summary LOG\n";
    return 2;
  }
  Summary s;
  try {
    manip::logging::read_log(argv[1], s);
  } catch (const std::exception& e) {
    std::cerr << "log_summary: " << e.what() << "\n";
    return 4;
  }
  std::cout << "sample_rate_hz " << s.sample_rate_hz << "\n"
            << "schema_version " << s.schema_version << "\n"
            << "source " << s.source << "\n"
            << "states " << s.states << "\n"
            << "last_cycle " << s.last_cycle << "\n"
            << "perturbation_states " << s.perturbation_states << "\n"
            << "onsets " << s.onsets << "\n"
            << "PHASE_PERTURBATION " << int{manip::state_t::PHASE_PERTURBATION} << "\n"
            << "MODE_RUNNING " << int{manip::state_t::MODE_RUNNING} << "\n";
  return 0;
}
