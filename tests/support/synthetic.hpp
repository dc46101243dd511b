#pragma once
// Small synthetic sessions for tests (linear-impedance person on the ideal
// admittance), in memory or as a log file.
#include <string>
#include <vector>

#include "manip/estimation/trial_data.hpp"
#include "manip/sim/linear_human.hpp"
#include "manip/sim/session_runner.hpp"

namespace manip::testutil {

// A short design: `movements` trials with one perturbed trial per angle
// (8 perturbed), shortened rests, no noise unless set afterwards.
sim::SessionDesign small_design(int movements = 10, std::uint64_t seed = 1);

struct MemorySession {
  estimation::SessionInfo info;
  std::vector<estimation::TrialData> trials;
  std::vector<estimation::TrialIssue> issues;
};
MemorySession simulate_in_memory(const sim::SessionDesign& d, const sim::LinearHumanParams& p);

// Captures the message stream (for tampering before writing a log).
struct Recorded {
  manip::session_t session;
  struct Item {
    int kind{0};  // 0 state, 1 event, 2 truth state, 3 truth impedance
    manip::state_t state{};
    manip::trial_event_t event{};
    manip::impedance_truth_t truth{};
  };
  std::vector<Item> items;
};
Recorded record(const sim::SessionDesign& d, const sim::LinearHumanParams& p);
void write_recorded(const Recorded& r, const std::string& path, bool with_session = true);
// A small good log (9 movements of the Table-1 person, no twins) written once
// into temp_dir(tag): the reference input the log-reader tests damage.
std::string write_small_good_log(const std::string& tag);

}  // namespace manip::testutil
