#include "synthetic.hpp"

#include "fixtures.hpp"
#include "manip/sim/presets.hpp"

namespace manip::testutil {

sim::SessionDesign small_design(int movements, std::uint64_t seed) {
  sim::SessionDesign d;
  d.n_movements = movements;
  d.reps_per_angle = 1;
  d.seed = seed;
  d.rest_before_s = 0.4;
  d.rest_after_s = 0.4;
  d.return_s = 0.3;
  d.encoder_resolution_m = 0.0;
  return d;
}

namespace {
struct Collector final : logging::SessionHandler {
  Recorded rec;
  void on_session(const manip::session_t& m) override { rec.session = m; }
  Recorded::Item& add(int kind) {
    rec.items.emplace_back();
    rec.items.back().kind = kind;
    return rec.items.back();
  }
  void on_state(const manip::state_t& m) override { add(0).state = m; }
  void on_trial_event(const manip::trial_event_t& m) override { add(1).event = m; }
  void on_truth_state(const manip::state_t& m) override { add(2).state = m; }
  void on_truth_impedance(const manip::impedance_truth_t& m) override { add(3).truth = m; }
};
}  // namespace

Recorded record(const sim::SessionDesign& d, const sim::LinearHumanParams& p0) {
  auto p = p0;
  p.sample_rate_hz = d.session.sample_rate_hz * d.substeps;
  sim::LinearImpedanceHuman h(p);
  Collector c;
  sim::run_session(d, h, c);
  return std::move(c.rec);
}

void write_recorded(const Recorded& r, const std::string& path, bool with_session) {
  logging::LogWritingHandler w(path);
  if (with_session) w.on_session(r.session);
  for (const auto& it : r.items) {
    switch (it.kind) {
      case 0: w.on_state(it.state); break;
      case 1: w.on_trial_event(it.event); break;
      case 2: w.on_truth_state(it.state); break;
      default: w.on_truth_impedance(it.truth);
    }
  }
  w.close();
}

MemorySession simulate_in_memory(const sim::SessionDesign& d, const sim::LinearHumanParams& p0) {
  MemorySession ms;
  estimation::TrialAssembler asmb([&](const estimation::SessionInfo& info, estimation::TrialData&& t) {
    ms.info = info;
    ms.trials.push_back(std::move(t));
  });
  auto p = p0;
  p.sample_rate_hz = d.session.sample_rate_hz * d.substeps;
  sim::LinearImpedanceHuman h(p);
  sim::run_session(d, h, asmb);
  asmb.finish();
  ms.info = asmb.session();
  ms.issues = asmb.issues();
  return ms;
}

std::string write_small_good_log(const std::string& tag) {
  const auto dir = temp_dir(tag);
  auto d = small_design(9);
  d.write_twins = false;
  write_recorded(record(d, sim::table1_person()), dir + "/good.lcm");
  return dir + "/good.lcm";
}

}  // namespace manip::testutil
