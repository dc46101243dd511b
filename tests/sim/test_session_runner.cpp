// The session runner writes what a lab log means: the controller's schedule
// and trigger, the documented phase and mode codes, one session description.
// Every check decodes a log written to disk and compares it with rules written
// out here from docs/schema-controller.md, not with the runner's own code.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/control/protocol.hpp"
#include "manip/control/trigger.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/schema/session_description.hpp"
#include "manip/sim/human_factory.hpp"
#include "manip/sim/presets.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

struct Log {
  manip::session_t session{};
  std::vector<manip::state_t> states;
  std::vector<manip::trial_event_t> events;
  int warnings{0};
};

struct Reader final : logging::SessionHandler {
  Log log;
  void on_session(const manip::session_t& m) override { log.session = m; }
  void on_state(const manip::state_t& m) override { log.states.push_back(m); }
  void on_trial_event(const manip::trial_event_t& m) override { log.events.push_back(m); }
  void on_warning(const std::string&) override { ++log.warnings; }
};

SessionDesign short_design(std::uint64_t seed) {
  SessionDesign d;
  d.n_movements = 12;
  d.reps_per_angle = 1;  // 8 perturbed
  d.seed = seed;
  d.rest_before_s = 0.4;
  d.rest_after_s = 0.6;
  d.return_s = 0.5;
  return d;
}

// Writes a manip_sim session (linear person from the factory) and reads it back.
Log simulate_to_disk(SessionDesign d, const std::string& name, bool noisy = true) {
  HumanSpec spec;
  spec.sample_rate_hz = d.session.sample_rate_hz;
  spec.linear = table1_person();
  if (noisy) apply_noise(NoiseLevel::realistic, d, spec.linear);
  auto human = make_human(spec);
  d.substeps = static_cast<int>(std::lround(1.0 / (human.step_s * d.session.sample_rate_hz)));
  const std::string path = testutil::temp_dir(name) + "/session.lcm";
  {
    logging::LogWritingHandler w(path);
    run_session(d, *human.model, w);
    w.close();
  }
  Reader r;
  logging::read_log(path, r);
  REQUIRE(r.log.warnings == 0);
  return r.log;
}

struct TrialSpan {
  std::int64_t start{-1}, onset{-1}, end{-1};
  bool perturbed{false};
  double angle_rad{0}, duration_s{0};
  Vec2 goal{Vec2::Zero()};
};

std::map<int, TrialSpan> trial_spans(const Log& log) {
  std::map<int, TrialSpan> t;
  for (const auto& e : log.events) {
    auto& s = t[e.trial];
    if (e.kind == manip::trial_event_t::START) {
      s.start = e.cycle;
      s.perturbed = e.perturbed;
      s.angle_rad = e.pert_angle_rad;
      s.duration_s = e.pert_duration_s;
      s.goal = Vec2(e.goal_shoulder_m[0], e.goal_shoulder_m[1]);
    } else if (e.kind == manip::trial_event_t::ONSET) {
      s.onset = e.cycle;
    } else if (e.kind == manip::trial_event_t::END) {
      s.end = e.cycle;
    }
  }
  return t;
}

}  // namespace

TEST_CASE("sim: every sample of a manip_sim log carries the documented phase and mode") {
  const Log log = simulate_to_disk(short_design(3), "sim_phase");
  const auto spans = trial_spans(log);
  const auto frame = schema::from_message(log.session).frame;
  const double fs = log.session.sample_rate_hz;
  REQUIRE(spans.size() == 12);
  for (const auto& [i, s] : spans) {
    REQUIRE(s.start >= 0);
    REQUIRE(s.end > s.start);
    CHECK((s.onset >= 0) == s.perturbed);  // every perturbed trial reached the trigger line
  }

  std::map<int, long> n_phase;
  for (const auto& st : log.states) {
    INFO("cycle " << st.cycle << " trial " << int(st.trial) << " phase " << int(st.phase));
    REQUIRE(st.mode == manip::state_t::MODE_RUNNING);
    ++n_phase[st.phase];
    const TrialSpan* in = nullptr;
    int index = -1;
    for (const auto& [i, s] : spans)
      if (st.cycle >= s.start && st.cycle <= s.end) {
        in = &s;
        index = i;
      }
    if (!in) {  // between trials (docs/schema-controller.md: RETURN, trial -1)
      REQUIRE(st.trial == -1);
      REQUIRE(st.phase == manip::state_t::PHASE_RETURN);
      REQUIRE(st.u_pert_workspace_n[0] == 0.0);
      continue;
    }
    REQUIRE(st.trial == index);
    const bool pert_active = in->onset >= 0 && st.cycle >= in->onset &&
                             static_cast<double>(st.cycle - in->onset) / fs < in->duration_s;
    const Vec2 x_sh = frame.point_to_shoulder(Vec2(st.x_workspace_m[0], st.x_workspace_m[1]));
    const Vec2 xd_sh = frame.vector_to_shoulder(Vec2(st.xd_workspace_mps[0], st.xd_workspace_mps[1]));
    const bool resting_in_goal = (x_sh - in->goal).norm() <= 0.01 && xd_sh.norm() <= 0.01;
    if (st.cycle == in->end) {
      REQUIRE(st.phase == manip::state_t::PHASE_RETURN);  // the END cycle still carries the index
    } else if (pert_active) {
      REQUIRE(st.phase == manip::state_t::PHASE_PERTURBATION);
    } else if (resting_in_goal) {
      REQUIRE(st.phase == manip::state_t::PHASE_GOAL_HOLD);
    } else {
      REQUIRE(st.phase == manip::state_t::PHASE_REACH);
    }
    // The perturbation force is applied exactly in PERTURBATION (zero at the onset cycle, eq. 22).
    const bool force = st.u_pert_workspace_n[0] != 0.0 || st.u_pert_workspace_n[1] != 0.0;
    if (force) REQUIRE(st.phase == manip::state_t::PHASE_PERTURBATION);
  }
  // 8 perturbed trials x T_pert (0.15 s at 4 kHz = 600 cycles) of PERTURBATION.
  CHECK(n_phase[manip::state_t::PHASE_PERTURBATION] == 8 * 600);
  CHECK(n_phase[manip::state_t::PHASE_REACH] > 0);
  CHECK(n_phase[manip::state_t::PHASE_GOAL_HOLD] > 0);
  CHECK(n_phase[manip::state_t::PHASE_RETURN] > 0);
  CHECK(n_phase.count(1) + n_phase.count(2) + n_phase.count(3) + n_phase.count(4) == n_phase.size());
}

TEST_CASE("sim: the onset is the controller trigger's: first crossing of the line moving towards the goal") {
  for (const bool downwards : {false, true}) {
    SessionDesign d = short_design(5);
    if (downwards) {  // goal below the start: the line is crossed with x2 decreasing
      d.start_shoulder_m = Vec2(0.0, 0.55);
      d.goal_shoulder_m = Vec2(0.0, 0.30);
      d.session.perturbation.trigger_x2_shoulder_m = 0.45;
    }
    const Log log = simulate_to_disk(d, downwards ? "sim_trigger_down" : "sim_trigger_up");
    const double line = log.session.trigger_x2_shoulder_m;
    const auto frame = schema::from_message(log.session).frame;
    const double dir = downwards ? -1.0 : 1.0;
    int checked = 0;
    for (const auto& [i, s] : trial_spans(log)) {
      if (!s.perturbed) continue;
      // The rule of paper §4.2 written out: previous measured sample strictly
      // before the line, this one at or beyond it, measured velocity towards the goal.
      std::int64_t expected = -1;
      double prev = 0.0;
      bool have_prev = false;
      for (const auto& st : log.states) {
        if (st.cycle < s.start || st.cycle > s.end) continue;
        const double x2 = frame.point_to_shoulder(Vec2(st.x_workspace_m[0], st.x_workspace_m[1])).y();
        const double xd2 = frame.vector_to_shoulder(Vec2(st.xd_workspace_mps[0], st.xd_workspace_mps[1])).y();
        if (have_prev && dir * (prev - line) < 0.0 && dir * (x2 - line) >= 0.0 && dir * xd2 > 0.0) {
          expected = st.cycle;
          break;
        }
        prev = x2;
        have_prev = true;
      }
      // And the controller's trigger fed with the logged measurements.
      control::PerturbationTrigger trig(line, log.session.sample_rate_hz);
      trig.arm(s.angle_rad, PerturbationProfile{}, dir);
      for (const auto& st : log.states) {
        if (st.cycle < s.start || st.cycle > s.end) continue;
        const double x2 = frame.point_to_shoulder(Vec2(st.x_workspace_m[0], st.x_workspace_m[1])).y();
        const double xd2 = frame.vector_to_shoulder(Vec2(st.xd_workspace_mps[0], st.xd_workspace_mps[1])).y();
        trig.update(st.cycle, x2, xd2);
      }
      INFO("trial " << i << (downwards ? " (downwards)" : " (upwards)"));
      REQUIRE(expected >= 0);
      CHECK(s.onset == expected);
      CHECK(trig.onset_cycle() == s.onset);
      ++checked;
    }
    CHECK(checked == 8);
  }
}

TEST_CASE("sim: the schedule is the controller's (same seed, same slots and angles as manip_rt)") {
  const SessionDesign d = short_design(20261123);
  control::ProtocolConfig pc;
  pc.movements = d.n_movements;
  pc.seed = d.seed;
  control::PerturbationConfig pe;
  pe.angles_deg = d.angles_deg;
  pe.repeats_per_angle = d.reps_per_angle;
  const auto ours = perturbation_schedule(d);
  const auto rt = control::make_schedule(pc, pe, pe.full_set());
  REQUIRE(ours.size() == rt.size());
  std::multiset<long> angles;
  for (std::size_t i = 0; i < ours.size(); ++i) {
    CHECK(ours[i].perturbed == rt[i].perturbed);
    CHECK(ours[i].angle_rad == rt[i].angle_rad);
    if (ours[i].perturbed) angles.insert(std::lround(ours[i].angle_rad * 180.0 / std::numbers::pi));
  }
  CHECK(angles == std::multiset<long>{30, 60, 120, 150, 210, 240, 300, 330});
  // The log's START events follow it.
  const Log log = simulate_to_disk(d, "sim_schedule", false);
  for (const auto& e : log.events)
    if (e.kind == manip::trial_event_t::START) {
      const auto& t = ours[static_cast<std::size_t>(e.trial)];
      CHECK(static_cast<bool>(e.perturbed) == t.perturbed);
      CHECK(e.pert_angle_rad == (t.perturbed ? t.angle_rad : 0.0));
    }
  SessionDesign bad = d;
  bad.n_movements = 5;
  CHECK_THROWS_AS(perturbation_schedule(bad), std::invalid_argument);
}

TEST_CASE("sim: one session description: a changed handle mass reaches the message and the plant") {
  SessionDesign d = short_design(9);
  d.session.m_handle_kg = Vec2(0.6, 0.45);
  d.session.participant_id = "P07";
  const Log log = simulate_to_disk(d, "sim_session", false);
  CHECK(log.session.m_handle_kg[0] == 0.6);
  CHECK(log.session.m_handle_kg[1] == 0.45);
  CHECK(log.session.m_adm_kg[0] == 5.0);
  CHECK(log.session.d_adm_nspm[1] == 15.0);
  CHECK(std::string(log.session.participant_id) == "P07");
  CHECK(log.session.sample_rate_hz == 4000.0);
  const auto back = schema::from_message(log.session);
  CHECK_FALSE(back.invalid_reason());
  CHECK(back.perturbation.trigger_x2_shoulder_m == d.session.perturbation.trigger_x2_shoulder_m);

  // The plant of eq. 19-20 takes the same numbers: a massless hand pushing with
  // a constant force from rest accelerates at F / (M_adm + M_handle) per axis.
  struct Push final : HumanModel {
    Vec2 x{Vec2::Zero()}, xd{Vec2::Zero()};
    void begin_trial(const ReachSpec&, std::uint64_t) override {}
    void endpoint_dynamics(Mat2& m, Vec2& h) override {
      m.setZero();
      h = Vec2(2.0, -3.0);
    }
    void advance(double dt, const Vec2& xdd) override {
      x += xd * dt;
      xd += xdd * dt;
    }
    Vec2 hand_position_m() const override { return x; }
    Vec2 hand_velocity_mps() const override { return xd; }
    double time_s() const override { return 0.0; }
  } push;
  const auto s = step_ideal_admittance(push, plant_params(d.session), Vec2::Zero(), 1e-3);
  CHECK(s.xdd_mps2.x() == Approx(2.0 / 5.6));
  CHECK(s.xdd_mps2.y() == Approx(-3.0 / 5.45));
  // Default: the schema's 0.25 kg handle (no other default exists).
  push.x.setZero();
  push.xd.setZero();
  const auto s0 = step_ideal_admittance(push, plant_params(default_sim_session()), Vec2::Zero(), 0.0);
  CHECK(s0.xdd_mps2.x() == Approx(2.0 / 5.25));
  // A rotated workspace: R diag(m) R^T.
  schema::SessionDescription rot = default_sim_session();
  rot.m_adm_kg = Vec2(4.0, 8.0);
  rot.m_handle_kg = Vec2(0.0, 0.0);
  rot.frame.rot_rad = std::numbers::pi / 2;
  const auto p = plant_params(rot);
  CHECK(p.m_adm_kg(0, 0) == Approx(8.0));
  CHECK(p.m_adm_kg(1, 1) == Approx(4.0));
  CHECK(std::abs(p.m_adm_kg(0, 1)) < 1e-12);
}

TEST_CASE("sim: a seeded session is reproducible byte for byte and seeds differ") {
  const auto bytes = [](std::uint64_t seed, const std::string& name) {
    SessionDesign d = short_design(seed);
    d.n_movements = 9;
    HumanSpec spec;
    spec.linear = table1_person();
    apply_noise(NoiseLevel::realistic, d, spec.linear);
    auto h = make_human(spec);
    const std::string path = testutil::temp_dir(name) + "/s.lcm";
    {
      logging::LogWritingHandler w(path);
      run_session(d, *h.model, w);
      w.close();
    }
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  const std::string a = bytes(11, "sim_det_a"), b = bytes(11, "sim_det_b"), c = bytes(12, "sim_det_c");
  REQUIRE(a.size() > 100000);
  CHECK(a == b);
  CHECK(a != c);
}
