// Perturbation trigger accuracy and the perturbation force in the loop's output.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

#include "manip/common/perturbation.hpp"
#include "manip/control/controller.hpp"
#include "manip/control/trigger.hpp"
#include "manip/trial_event_t.hpp"
#include "test_support.hpp"

using manip::Vec2;
using namespace manip::control;
using namespace manip::runtime;

TEST_CASE("trigger fires in the first crossing cycle, towards the goal, once", "[trigger]") {
  PerturbationTrigger t(0.40, 4000.0);
  manip::PerturbationProfile prof{0.15, 15.0};
  SECTION("not armed: never") {
    for (int k = 0; k < 10; ++k) CHECK_FALSE(t.update(k, 0.38 + 0.005 * k, 0.1));
    CHECK_FALSE(t.fired());
  }
  SECTION("armed: exactly at the crossing sample (previous < trigger <= current)") {
    t.arm(0.5, prof, +1.0);
    CHECK_FALSE(t.update(0, 0.398, 0.1));
    CHECK_FALSE(t.update(1, 0.3999999, 0.1));
    CHECK(t.update(2, 0.40, 0.1));  // reaching the line counts as crossing
    CHECK(t.onset_cycle() == 2);
    CHECK_FALSE(t.update(3, 0.401, 0.1));
    // back and forth again: never twice
    CHECK_FALSE(t.update(4, 0.39, -0.1));
    CHECK_FALSE(t.update(5, 0.41, 0.1));
    CHECK(t.onset_cycle() == 2);
  }
  SECTION("crossing while the velocity points away from the goal does not fire") {
    t.arm(0.5, prof, +1.0);
    t.update(0, 0.399, 0.1);
    CHECK_FALSE(t.update(1, 0.401, -0.05));  // encoder says forward, velocity says backward: no
    CHECK_FALSE(t.update(2, 0.399, -0.05));
    CHECK(t.update(3, 0.4005, 0.05));
    CHECK(t.onset_cycle() == 3);
  }
  SECTION("crossing in the opposite direction does not fire") {
    t.arm(0.5, prof, +1.0);
    t.update(0, 0.41, -0.1);
    CHECK_FALSE(t.update(1, 0.39, -0.1));
    CHECK_FALSE(t.fired());
  }
  SECTION("goal at smaller x2: direction -1") {
    t.arm(0.5, prof, -1.0);
    t.update(0, 0.45, -0.1);
    CHECK_FALSE(t.update(1, 0.41, -0.1));
    CHECK(t.update(2, 0.40, -0.1));
  }
  SECTION("force follows eq. 22-23 sampled at the cycle times after onset") {
    t.arm(2.0, prof, +1.0);
    t.update(0, 0.39, 0.1);
    REQUIRE(t.update(1, 0.41, 0.1));
    for (int k = 1; k < 1000; ++k) {
      const Vec2 f = t.force_shoulder_n(k);
      const Vec2 e = prof.force_n((k - 1) / 4000.0, 2.0);
      REQUIRE(f[0] == Approx(e[0]).margin(1e-12));
      REQUIRE(f[1] == Approx(e[1]).margin(1e-12));
    }
    CHECK(t.force_shoulder_n(1).norm() == 0.0);            // u_p(0) = 0
    CHECK(t.force_shoulder_n(2).norm() > 0.0);             // rises from the next cycle
    CHECK(t.active(1 + 599));                              // 599 samples < 150 ms
    CHECK_FALSE(t.active(1 + 600));                        // T_pert = 600 cycles
    CHECK(t.force_shoulder_n(1 + 300).norm() == Approx(15.0).epsilon(1e-3));  // peak at T/2
  }
}

namespace {

struct Scripted {
  RtConfig cfg;
  RecordQueue log{1 << 20};
  Controller ctl;
  test_support::Drained out;
  explicit Scripted(const RtConfig& c) : cfg(c), ctl(c, {&log, nullptr, nullptr}, ControllerOptions{false, false, 0, 0}) {}
  void step_shoulder(std::int64_t k, const Vec2& x_sh, const Vec2& xd_sh) {
    const Vec2 xw = cfg.session.frame.point_to_workspace(x_sh);
    const Vec2 vw = cfg.session.frame.vector_to_workspace(xd_sh);
    ctl.step(test_support::reading(k, xw, vw), k);
    if ((k & 1023) == 0) test_support::drain(log, out);
  }
  void finish() { test_support::drain(log, out); }
};

// Hand rests at start, reaches at constant speed to the goal, rests. Returns
// the first cycle at which x2 >= trigger (the expected onset).
std::int64_t run_reach(Scripted& s, std::int64_t& k, double speed, std::int64_t rest_cycles) {
  const Vec2 start = s.cfg.protocol.start_shoulder_m, goal = s.cfg.protocol.goal_shoulder_m;
  const double dt = s.cfg.dt_s();
  std::int64_t crossing = -1;
  const std::int64_t k_end_rest = k + rest_cycles;
  for (; k < k_end_rest; ++k) s.step_shoulder(k, start, Vec2::Zero());
  const std::int64_t k0 = k;
  for (;; ++k) {
    const double x2 = start.y() + speed * static_cast<double>(k - k0) * dt;
    if (x2 >= goal.y()) break;
    if (crossing < 0 && x2 >= s.cfg.session.perturbation.trigger_x2_shoulder_m) crossing = k;
    s.step_shoulder(k, Vec2(0.0, x2), Vec2(0.0, speed));
  }
  const std::int64_t k_goal = k + rest_cycles;
  for (; k < k_goal; ++k) s.step_shoulder(k, goal, Vec2::Zero());
  return crossing;
}

}  // namespace

TEST_CASE("controller: onset = first crossing cycle on a perturbed trial, logged with the force", "[trigger][controller]") {
  RtConfig cfg = test_support::shipped_config(test_support::scripted({{"protocol.movements", "1"}, {"protocol.perturbed_trials", "1"}}));
  Scripted s(cfg);
  std::int64_t k = 0;
  const std::int64_t crossing = run_reach(s, k, 0.1, 2500);
  s.finish();
  REQUIRE(crossing > 0);
  int onsets = 0, starts = 0, ends = 0;
  const TrialEventRecord* onset = nullptr;
  for (const auto& e : s.out.events) {
    if (e.kind == manip::trial_event_t::ONSET) {
      ++onsets;
      onset = &e;
    }
    starts += e.kind == manip::trial_event_t::START;
    ends += e.kind == manip::trial_event_t::END;
  }
  REQUIRE(onsets == 1);
  CHECK(starts == 1);
  CHECK(ends == 1);
  CHECK(onset->cycle == crossing);
  CHECK(onset->perturbed);
  CHECK(onset->pert_amplitude_n == 15.0);
  CHECK(onset->pert_duration_s == 0.15);
  // u_pert in every state: eq. 23 at (k - k0)/fs, rotated into the workspace frame (identity here)
  const manip::PerturbationProfile prof{0.15, 15.0};
  for (const auto& st : s.out.states) {
    const Vec2 e = cfg.session.frame.vector_to_workspace(prof.force_n(static_cast<double>(st.cycle - crossing) / 4000.0,
                                                               onset->pert_angle_rad));
    REQUIRE(st.u_pert_workspace_n[0] == Approx(e[0]).margin(1e-12));
    REQUIRE(st.u_pert_workspace_n[1] == Approx(e[1]).margin(1e-12));
    if (st.cycle > crossing && st.cycle < crossing + 600) REQUIRE(st.phase == static_cast<int>(Phase::kPerturbation));
  }
  // trial index on every state: the trial's index inside it, -1 outside
  for (const auto& st : s.out.states) {
    const bool inside = st.cycle >= s.out.events.front().cycle && st.cycle <= s.out.events.back().cycle;
    REQUIRE(st.trial == (inside ? 0 : -1));
  }
}

TEST_CASE("controller: no onset on unperturbed trials", "[trigger][controller]") {
  RtConfig cfg = test_support::shipped_config(test_support::scripted({{"protocol.movements", "1"}, {"protocol.perturbed_trials", "0"}}));
  Scripted s(cfg);
  std::int64_t k = 0;
  REQUIRE(run_reach(s, k, 0.1, 2500) > 0);
  s.finish();
  for (const auto& e : s.out.events) CHECK(e.kind != manip::trial_event_t::ONSET);
  for (const auto& st : s.out.states) REQUIRE(Vec2(st.u_pert_workspace_n[0], st.u_pert_workspace_n[1]).norm() == 0.0);
}

TEST_CASE("controller: onset in the rotated/shifted frame uses the shoulder-frame x2", "[trigger][controller][frames]") {
  RtConfig cfg = test_support::shipped_config(test_support::scripted(
      {{"protocol.movements", "1"}, {"protocol.perturbed_trials", "1"}, {"frames.workspace_to_shoulder_rot_rad", "0.1"}}));
  Scripted s(cfg);
  std::int64_t k = 0;
  const std::int64_t crossing = run_reach(s, k, 0.08, 2500);
  s.finish();
  int n = 0;
  for (const auto& e : s.out.events)
    if (e.kind == manip::trial_event_t::ONSET) {
      ++n;
      CHECK(e.cycle == crossing);
    }
  CHECK(n == 1);
}
