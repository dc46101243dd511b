// Hidden force-sensor mechanisms (include/manip/sim/hidden_effects.hpp:
// sensor_lag, sensor_offset, sensor_drift; issue 11): parsing, the admittance
// rendering from the reading the log records, the apparent truth staying the
// person's, and a bias of the reading pushing the handle.
#include <catch2/catch.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "manip/common/errors.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

struct States final : logging::SessionHandler {
  std::vector<manip::state_t> states;
  void on_session(const manip::session_t&) override {}
  void on_state(const manip::state_t& m) override { states.push_back(m); }
  void on_trial_event(const manip::trial_event_t&) override {}
};

struct Run {
  std::vector<manip::state_t> states;
  SessionRunSummary sum;
  SessionDesign design;
};

Run run_sensor(const std::vector<HiddenEffect>& effects, std::uint64_t hidden_seed = 2) {
  auto base = testutil::small_design(12);
  base.reps_per_angle = 1;
  auto hs = make_hidden_session(base, table1_person(), effects, hidden_seed);
  States st;
  Run r;
  r.sum = run_session(hs.design, *hs.person, st);
  r.states = std::move(st.states);
  r.design = hs.design;
  return r;
}

}  // namespace

TEST_CASE("hidden sensor: parse sensor_lag, sensor_offset, sensor_drift and refuse bad text naming it") {
  CHECK(parse_hidden_effect("sensor_lag:0.001").mechanism == HiddenMechanism::sensor_lag);
  CHECK(parse_hidden_effect("sensor_offset:2").mechanism == HiddenMechanism::sensor_offset);
  const auto e = parse_hidden_effect("sensor_drift:0.05");
  CHECK(e.mechanism == HiddenMechanism::sensor_drift);
  CHECK(e.magnitude == 0.05);
  CHECK(to_string(e).rfind("sensor_drift:0.05", 0) == 0);
  for (const char* bad : {"sensor_lag", "sensor_lag:2", "sensor_lag:1ms", "sensor_offset:-1", "sensor_drift:x", "sensor:1"}) {
    INFO(bad);
    CHECK_THROWS_AS(parse_hidden_effect(bad), UsageError);
    try {
      (void)parse_hidden_effect(bad);
    } catch (const UsageError& err) {
      CHECK(std::string(err.what()).find(bad) != std::string::npos);
    }
  }
  const auto hs = make_hidden_session(testutil::small_design(12), table1_person(),
                                      {parse_hidden_effect("sensor_lag:0.002"), parse_hidden_effect("sensor_offset:3"),
                                       parse_hidden_effect("sensor_drift:0.1")},
                                      1);
  CHECK(hs.design.hidden_sensor_lag_s == 0.002);
  CHECK(hs.design.hidden_sensor_offset_n == 3.0);
  CHECK(hs.design.hidden_sensor_drift_nps == 0.1);
}

TEST_CASE("hidden sensor: the admittance renders from the reading the log records (M_adm xdd + D_adm xd = f_r + u_pert)") {
  for (const char* h : {"sensor_lag:0.002", "sensor_offset:3", "sensor_drift:0.1"}) {
    INFO(h);
    const auto r = run_sensor({parse_hidden_effect(h)});
    const auto& s = r.design.session;
    double worst = 0.0;
    for (const auto& st : r.states)
      for (int a = 0; a < 2; ++a) {
        const double lhs = s.m_adm_kg[a] * st.xdd_ref_workspace_mps2[a] + s.d_adm_nspm[a] * st.xd_ref_workspace_mps[a];
        worst = std::max(worst, std::abs(lhs - st.u_pert_workspace_n[a] - st.f_sensor_workspace_n[a]));
      }
    CHECK(worst < 1e-9);
  }
  // The lagged filter starts at 0: the first reading of the session is the bias alone.
  const auto r = run_sensor({parse_hidden_effect("sensor_lag:0.002"), parse_hidden_effect("sensor_offset:3")});
  CHECK(r.states.front().f_sensor_workspace_n[0] == Approx(3.0).margin(1e-12));
  CHECK(r.states.front().f_sensor_workspace_n[1] == Approx(3.0).margin(1e-12));
}

TEST_CASE("hidden sensor: the apparent truth stays the person's with a lag, a bias of the reading pushes the handle") {
  static const auto clean = run_sensor({});
  REQUIRE(clean.sum.apparent);
  const auto& k0 = clean.sum.apparent->k_npm;
  const auto& d0 = clean.sum.apparent->d_nspm;
  {
    // Eq. 21 on the exact signals with the reading's error moved to the
    // plant's extra force: the person's D, K (the linear person; measured
    // 0.03 % for D and K). Not so for an offset or drift: they move the hand, so the
    // onset postures and M_BSP there (eq. 16, fixed in the fit) differ from
    // the person's constant inertia, and the apparent D, K with them
    // (measured here, hidden seed 2, 12 movements: 5 N offset K 25 %, D 30 %;
    // drift 0.1 N/s K 10 %, D 12 %).
    const auto r = run_sensor({parse_hidden_effect("sensor_lag:0.003")});
    REQUIRE(r.sum.apparent);
    CHECK((r.sum.apparent->k_npm - k0).norm() < 0.02 * k0.norm());
    CHECK((r.sum.apparent->d_nspm - d0).norm() < 0.02 * d0.norm());
  }
  // An offset is a constant force on the admittance: the hand at rest in the
  // start target before the first go cue sits away from the clean session's
  // (person's K: 100-300 N/m, 5 N on both workspace axes -> centimetres).
  const auto off = run_sensor({parse_hidden_effect("sensor_offset:5")});
  const std::size_t rest = 1500;  // 0.375 s: inside the first 0.4 s rest
  REQUIRE(off.states.size() > rest);
  const double dev = std::hypot(off.states[rest].x_workspace_m[0] - clean.states[rest].x_workspace_m[0],
                                off.states[rest].x_workspace_m[1] - clean.states[rest].x_workspace_m[1]);
  CHECK(dev > 0.005);
  // A drift grows over the session: the deviation at the end of the last
  // trial's rest is larger than in the first.
  const auto dr = run_sensor({parse_hidden_effect("sensor_drift:0.1")});
  REQUIRE(dr.states.size() == clean.states.size());
  const auto dev_at = [&](std::size_t i) {
    return std::hypot(dr.states[i].x_workspace_m[0] - clean.states[i].x_workspace_m[0],
                      dr.states[i].x_workspace_m[1] - clean.states[i].x_workspace_m[1]);
  };
  CHECK(dev_at(dr.states.size() - 1) > 5 * dev_at(rest));
}
