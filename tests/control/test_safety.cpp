// Safety: the mode machine transition by transition, the condition checks, and
// the controller reaching the safe law in the same cycle for every fault.
#include <catch2/catch.hpp>

#include <cmath>
#include <functional>
#include <limits>

#include "manip/command_t.hpp"
#include "manip/control/controller.hpp"
#include "manip/control/safety.hpp"
#include "manip/trial_event_t.hpp"
#include "test_support.hpp"

using manip::Vec2;
using namespace manip::control;
using namespace manip::runtime;

namespace {
SafetyStateMachine in_mode(Mode m) {
  SafetyStateMachine sm;
  switch (m) {
    case Mode::kInit: break;
    case Mode::kIdle: sm.inputs_ok(); break;
    case Mode::kRunning: sm.inputs_ok(); sm.start_session(); break;
    case Mode::kPaused: sm.inputs_ok(); sm.start_session(); sm.pause(); break;
    case Mode::kFault: sm.inputs_ok(); sm.raise(fault::kVelocity); break;
    case Mode::kEStop: sm.inputs_ok(); sm.estop(); break;
    case Mode::kDone: sm.inputs_ok(); sm.start_session(); sm.session_done(); break;
    case Mode::kStopped: sm.shutdown(); break;
  }
  REQUIRE(sm.mode() == m);
  return sm;
}
const Mode kAll[] = {Mode::kInit, Mode::kIdle,  Mode::kRunning, Mode::kPaused,
                     Mode::kFault, Mode::kEStop, Mode::kDone,    Mode::kStopped};
}  // namespace

TEST_CASE("mode machine: every operation from every mode", "[safety]") {
  struct Row {
    const char* name;
    std::function<Reject(SafetyStateMachine&)> op;
    // expected mode after the op from each of kAll (same order), and whether accepted
    Mode after[8];
    bool ok[8];
  };
  using M = Mode;
  const Row rows[] = {
      {"start_session", [](SafetyStateMachine& s) { return s.start_session(); },
       {M::kInit, M::kRunning, M::kRunning, M::kPaused, M::kFault, M::kEStop, M::kDone, M::kStopped},
       {false, true, false, false, false, false, false, false}},
      {"pause", [](SafetyStateMachine& s) { return s.pause(); },
       {M::kInit, M::kIdle, M::kPaused, M::kPaused, M::kFault, M::kEStop, M::kDone, M::kStopped},
       {false, false, true, false, false, false, false, false}},
      {"resume", [](SafetyStateMachine& s) { return s.resume(); },
       {M::kInit, M::kIdle, M::kRunning, M::kRunning, M::kFault, M::kEStop, M::kDone, M::kStopped},
       {false, false, false, true, false, false, false, false}},
      {"stop_session", [](SafetyStateMachine& s) { return s.stop_session(); },
       {M::kInit, M::kDone, M::kDone, M::kDone, M::kFault, M::kEStop, M::kDone, M::kStopped},
       {false, true, true, true, false, false, false, false}},
      {"fault_reset (clear)", [](SafetyStateMachine& s) { return s.fault_reset(0); },
       {M::kInit, M::kIdle, M::kRunning, M::kPaused, M::kIdle, M::kIdle, M::kDone, M::kStopped},
       {false, false, false, false, true, true, false, false}},
      {"fault_reset (condition present)", [](SafetyStateMachine& s) { return s.fault_reset(fault::kWorkspace); },
       {M::kInit, M::kIdle, M::kRunning, M::kPaused, M::kFault, M::kEStop, M::kDone, M::kStopped},
       {false, false, false, false, false, false, false, false}},
      {"raise", [](SafetyStateMachine& s) { s.raise(fault::kWorkspace); return Reject::kNone; },
       {M::kFault, M::kFault, M::kFault, M::kFault, M::kFault, M::kEStop, M::kFault, M::kStopped},
       {true, true, true, true, true, true, true, true}},
      {"estop", [](SafetyStateMachine& s) { s.estop(); return Reject::kNone; },
       {M::kEStop, M::kEStop, M::kEStop, M::kEStop, M::kEStop, M::kEStop, M::kEStop, M::kStopped},
       {true, true, true, true, true, true, true, true}},
      {"shutdown", [](SafetyStateMachine& s) { s.shutdown(); return Reject::kNone; },
       {M::kStopped, M::kStopped, M::kStopped, M::kStopped, M::kStopped, M::kStopped, M::kStopped, M::kStopped},
       {true, true, true, true, true, true, true, true}},
  };
  for (const auto& row : rows) {
    for (int i = 0; i < 8; ++i) {
      SafetyStateMachine sm = in_mode(kAll[i]);
      const Reject r = row.op(sm);
      INFO(row.name << " from " << mode_name(kAll[i]));
      CHECK(sm.mode() == row.after[i]);
      CHECK((r == Reject::kNone) == row.ok[i]);
      const bool safe = sm.mode() == Mode::kInit || sm.mode() == Mode::kFault || sm.mode() == Mode::kEStop ||
                        sm.mode() == Mode::kStopped;
      CHECK(sm.safe_law() == safe);
    }
  }
}

TEST_CASE("mode machine: faults latch until reset, which returns to PAUSED once a session started", "[safety]") {
  SafetyStateMachine sm = in_mode(Mode::kRunning);
  CHECK(sm.raise(fault::kVelocity | fault::kWorkspace) == (fault::kVelocity | fault::kWorkspace));
  CHECK(sm.raise(fault::kVelocity) == 0u);  // already latched: nothing new
  CHECK(sm.latched() == (fault::kVelocity | fault::kWorkspace));
  CHECK(sm.fault_reset(fault::kWorkspace) == Reject::kConditionPresent);
  CHECK(sm.fault_reset(0) == Reject::kNone);
  CHECK(sm.latched() == 0u);
  CHECK(sm.mode() == Mode::kPaused);
  // e-stop while faulted: ESTOP latches both
  sm.raise(fault::kTracking);
  sm.estop();
  CHECK(sm.mode() == Mode::kEStop);
  CHECK(sm.latched() == (fault::kTracking | fault::kLcmEStop));
  sm.raise(fault::kVelocity);
  CHECK(sm.mode() == Mode::kEStop);  // a fault does not downgrade an e-stop
}

TEST_CASE("safety monitor: each condition", "[safety]") {
  const RtConfig cfg;
  SafetyMonitor m(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  FaultDetail d;
  auto r = test_support::reading(0, Vec2(0.0, 0.0));
  CHECK(m.check_inputs(r, false, false, d) == 0u);
  auto check = [&](std::uint32_t expect, const std::function<void(SensorReading&)>& mod, bool overran = false,
                   bool logger = false) {
    SafetyMonitor mon(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
    FaultDetail det;
    auto rr = test_support::reading(1, Vec2(0.0, 0.0));
    mod(rr);
    const std::uint32_t f = mon.check_inputs(rr, overran, logger, det);
    CHECK(f == expect);
    CHECK((expect == 0u ? det.bit == 0u : (det.bit & expect) != 0u));
  };
  check(fault::kWorkspace, [](SensorReading& x) { x.x_workspace_m[1] = -0.1471; });
  check(fault::kVelocity, [](SensorReading& x) { x.xd_workspace_mps[0] = 1.01; });
  check(fault::kHandleForce, [](SensorReading& x) { x.f_sensor_workspace_n[0] = 61.0; });
  check(fault::kHandleForce | fault::kSensorSaturated, [](SensorReading& x) { x.f_sensor_workspace_n[1] = -100.0; });
  check(fault::kSensorInvalid, [](SensorReading& x) { x.f_sensor_workspace_n[1] = std::numeric_limits<double>::quiet_NaN(); });
  check(fault::kSensorInvalid, [](SensorReading& x) { x.x_workspace_m[0] = std::numeric_limits<double>::infinity(); });
  check(fault::kBackend, [](SensorReading& x) { x.status |= backend_status::kDriveFault; });
  check(fault::kBackend, [](SensorReading& x) { x.status |= backend_status::kBackendError; });
  check(fault::kHardwareEStop, [](SensorReading& x) { x.status |= backend_status::kHwEStopOpen; });
  check(fault::kLogger, [](SensorReading&) {}, false, true);
  check(0u, [](SensorReading&) {}, true);  // one overrun is tolerated

  // stale: the force sample unchanged for stale_cycles cycles
  SafetyMonitor s2(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  std::uint32_t f = 0;
  for (int k = 0; k < 10; ++k) {
    auto rr = test_support::reading(k, Vec2::Zero());
    rr.force_seq = 7;
    FaultDetail dd;
    f = s2.check_inputs(rr, false, false, dd);
    if (k < cfg.safety.stale_cycles) REQUIRE(f == 0u);
  }
  CHECK(f == fault::kSensorStale);

  // overruns: 3 consecutive
  SafetyMonitor s3(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  for (int k = 0; k < 3; ++k) {
    FaultDetail dd;
    f = s3.check_inputs(test_support::reading(k, Vec2::Zero()), true, false, dd);
    if (k < 2) REQUIRE(f == 0u);
  }
  CHECK(f == fault::kOverrun);
  // overruns: 40 within one second, never 3 in a row
  SafetyMonitor s4(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  int first_fault = -1;
  for (int k = 0; k < 4000 && first_fault < 0; ++k) {
    FaultDetail dd;
    if (s4.check_inputs(test_support::reading(k, Vec2::Zero()), k % 50 == 0, false, dd)) first_fault = k;
  }
  CHECK(first_fault == 39 * 50);  // the 40th overrun
  // ... but 40 spread over more than a second are fine
  SafetyMonitor s5(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  bool any = false;
  for (int k = 0; k < 20000; ++k) {
    FaultDetail dd;
    any |= s5.check_inputs(test_support::reading(k, Vec2::Zero()), k % 110 == 0, false, dd) != 0u;
  }
  CHECK_FALSE(any);

  // outputs
  FaultDetail od;
  CHECK(m.check_outputs(Vec2(201.0, 0.0), Vec2::Zero(), Vec2::Zero(), Vec2::Zero(), od) == fault::kMotorForce);
  CHECK(m.check_outputs(Vec2::Zero(), Vec2(30.1, 0.0), Vec2::Zero(), Vec2::Zero(), od) == fault::kPerturbation);
  CHECK(m.check_outputs(Vec2::Zero(), Vec2::Zero(), Vec2(0.0, 0.0101), Vec2::Zero(), od) == fault::kTracking);
  CHECK(m.check_outputs(Vec2(std::nan(""), 0.0), Vec2::Zero(), Vec2::Zero(), Vec2::Zero(), od) == fault::kMotorForce);
}

TEST_CASE("safety monitor: virtual walls and safe laws", "[safety]") {
  RtConfig cfg;
  SafetyMonitor m(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  CHECK(m.wall_force(Vec2(0.1, -0.1), Vec2(1.0, 1.0)).norm() == 0.0);
  const Vec2 w = m.wall_force(Vec2(0.14, -0.14), Vec2(0.1, -0.1));
  CHECK(w[0] == Approx(-5000.0 * 0.005 - 100.0 * 0.1));
  CHECK(w[1] == Approx(5000.0 * 0.005 + 100.0 * 0.1));
  CHECK(m.safe_force(Vec2(0.1, -0.2))[0] == Approx(-3.0));
  CHECK(m.safe_force(Vec2(0.1, -0.2))[1] == Approx(6.0));
  CHECK(m.safe_force(Vec2(100.0, std::nan("")))[0] == Approx(-200.0));  // clamped
  CHECK(m.safe_force(Vec2(100.0, std::nan("")))[1] == 0.0);             // NaN never reaches a drive
  cfg.safety.safe_law = SafeLaw::kZeroForce;
  SafetyMonitor z(cfg.safety, cfg.cycle, cfg.session.sample_rate_hz);
  CHECK(z.safe_force(Vec2(0.1, -0.2)).norm() == 0.0);
}

// --- the controller: every fault reaches the safe law in the cycle it appears ---

namespace {

struct Rig {
  RtConfig cfg;
  RecordQueue log{1 << 16};
  CommandQueue cmds{64};
  Controller ctl;
  test_support::Drained out;
  std::int64_t k{0};
  Vec2 x;
  explicit Rig(const RtConfig& c, bool stop_on_fault = false)
      : cfg(c),
        ctl(c, {&log, nullptr, &cmds}, ControllerOptions{false, stop_on_fault, 0, 0}),
        x(c.session.frame.point_to_workspace(c.protocol.start_shoulder_m)) {}
  // The "plant" follows the admittance reference exactly (ideal tracking).
  const ActuatorCommand& step(const std::function<void(SensorReading&)>& mod = nullptr, bool overran = false) {
    SensorReading r = test_support::reading(k, x);
    if (mod) mod(r);
    const ActuatorCommand& c = ctl.step(r, k, overran);
    x = ctl.admittance().x();
    ++k;
    test_support::drain(log, out);
    return c;
  }
  void command(std::int8_t kind, std::int64_t seq = 1) {
    Command c;
    c.kind = kind;
    c.seq = seq;
    REQUIRE(cmds.try_push(c));
  }
};

}  // namespace

TEST_CASE("controller: every fault reaches the safe law in the same cycle", "[safety][controller]") {
  struct Case {
    const char* name;
    std::uint32_t bit;
    std::function<void(SensorReading&)> mod;
    bool overran;
    int repeat;  // cycles with the condition until the fault (stale/overrun need several)
    std::function<void(RtConfig&)> cfg_mod;
  };
  const Case cases[] = {
      {"workspace", fault::kWorkspace, [](SensorReading& r) { r.x_workspace_m[0] = 0.148; }, false, 1, nullptr},
      {"velocity", fault::kVelocity, [](SensorReading& r) { r.xd_workspace_mps[1] = -1.5; }, false, 1, nullptr},
      {"handle force", fault::kHandleForce, [](SensorReading& r) { r.f_sensor_workspace_n[0] = 70.0; }, false, 1, nullptr},
      {"saturation", fault::kSensorSaturated, [](SensorReading& r) { r.f_sensor_workspace_n[0] = 150.0; }, false, 1, nullptr},
      {"NaN", fault::kSensorInvalid, [](SensorReading& r) { r.f_sensor_workspace_n[1] = std::nan(""); }, false, 1, nullptr},
      {"stale", fault::kSensorStale, [](SensorReading& r) { r.force_seq = 1; }, false, 5, nullptr},
      {"drive fault", fault::kBackend, [](SensorReading& r) { r.status |= backend_status::kDriveFault; }, false, 1, nullptr},
      {"hardware e-stop", fault::kHardwareEStop, [](SensorReading& r) { r.status |= backend_status::kHwEStopOpen; }, false, 1, nullptr},
      {"overrun", fault::kOverrun, nullptr, true, 3, nullptr},
      {"motor force", fault::kMotorForce, [](SensorReading& r) { r.x_workspace_m[0] += 0.005; }, false, 1, nullptr},
      {"tracking", fault::kTracking, [](SensorReading& r) { r.x_workspace_m[1] += 0.02; }, false, 1,
       [](RtConfig& c) { c.safety.max_motor_force_n = 1e9; }},
  };
  for (const auto& cs : cases) {
    INFO(cs.name);
    RtConfig cfg;
    if (cs.cfg_mod) cs.cfg_mod(cfg);
    Rig rig(cfg);
    for (int i = 0; i < 2001; ++i) rig.step();
    REQUIRE(rig.ctl.mode() == Mode::kRunning);
    const ActuatorCommand* c = nullptr;
    for (int i = 0; i < cs.repeat; ++i) {
      c = &rig.step(cs.mod, cs.overran);
      if (i + 1 < cs.repeat) REQUIRE(rig.ctl.mode() == Mode::kRunning);
    }
    CHECK(rig.ctl.mode() == Mode::kFault);
    CHECK((rig.ctl.state_machine().latched() & cs.bit) != 0u);
    CHECK(c->send);  // written to the drives at once, even between drive ticks
    CHECK(c->enable);
    const auto& st = rig.ctl.last_state();
    const Vec2 safe = -cfg.safety.safe_damping_nspm *
                      Vec2(std::isfinite(st.xd_workspace_mps[0]) ? st.xd_workspace_mps[0] : 0.0,
                           std::isfinite(st.xd_workspace_mps[1]) ? st.xd_workspace_mps[1] : 0.0);
    for (int i = 0; i < 2; ++i) CHECK(c->f_motor_n[i] == Approx(std::clamp(safe[i], -200.0, 200.0)));
    CHECK(st.mode == static_cast<int>(Mode::kFault));
    CHECK(st.u_pert_workspace_n[0] == 0.0);
    REQUIRE(rig.out.faults.size() == 1);
    CHECK(rig.out.faults[0].cycle == rig.k - 1);
    CHECK((rig.out.faults[0].new_flags & cs.bit) != 0u);
    // the running trial was aborted in that cycle
    REQUIRE_FALSE(rig.out.events.empty());
    CHECK(rig.out.events.back().kind == manip::trial_event_t::ABORT);
    CHECK(rig.out.events.back().reason == AbortReason::kFault);
    CHECK(rig.out.events.back().cycle == rig.k - 1);
  }
}

TEST_CASE("controller: perturbation beyond its limit faults in the onset window", "[safety][controller]") {
  RtConfig cfg = test_support::shipped_config(test_support::scripted({{"protocol.movements", "1"}, {"protocol.perturbed_trials", "1"}}));
  cfg.safety.max_pert_amplitude_n = 5.0;  // below A_pert: bypasses the config check on purpose
  RecordQueue log(1 << 20);
  Controller ctl(cfg, {&log, nullptr, nullptr}, ControllerOptions{false, false, 0, 0});
  std::int64_t k = 0;
  const Vec2 s = cfg.session.frame.point_to_workspace(cfg.protocol.start_shoulder_m);
  for (; k < 2100; ++k) ctl.step(test_support::reading(k, s), k);
  for (int i = 0; ctl.mode() == Mode::kRunning && i < 20000; ++i, ++k) {
    const Vec2 x = s + Vec2(0.0, 0.1 * i / 4000.0);
    const ActuatorCommand& c = ctl.step(test_support::reading(k, x, Vec2(0.0, 0.1)), k);
    if (ctl.mode() == Mode::kFault) {
      CHECK(c.send);
      CHECK((ctl.state_machine().latched() & fault::kPerturbation) != 0u);
      CHECK(ctl.last_state().u_pert_workspace_n[0] == 0.0);  // not applied
    }
  }
  CHECK(ctl.mode() == Mode::kFault);
}

TEST_CASE("controller: LCM e-stop -> safe law in the same cycle, reset only when clear", "[safety][controller][commands]") {
  RtConfig cfg;
  Rig rig(cfg);
  for (int i = 0; i < 2001; ++i) rig.step();
  REQUIRE(rig.ctl.mode() == Mode::kRunning);
  rig.command(manip::command_t::ESTOP, 5);
  const ActuatorCommand& c = rig.step();
  CHECK(rig.ctl.mode() == Mode::kEStop);
  CHECK(c.send);
  CHECK((rig.ctl.state_machine().latched() & fault::kLcmEStop) != 0u);
  REQUIRE(rig.out.results.size() == 1);
  CHECK(rig.out.results[0].accepted);
  CHECK(rig.out.results[0].mode_after == Mode::kEStop);
  REQUIRE(rig.out.faults.size() == 1);
  CHECK(rig.out.faults[0].new_flags == fault::kLcmEStop);
  // reset while a condition is present: rejected, naming it
  rig.x = Vec2(0.149, 0.0);
  rig.step();
  rig.command(manip::command_t::FAULT_RESET, 6);
  rig.step();
  REQUIRE(rig.out.results.size() == 2);
  CHECK_FALSE(rig.out.results[1].accepted);
  CHECK(rig.out.results[1].reason == Reject::kConditionPresent);
  CHECK((rig.out.results[1].detail & fault::kWorkspace) != 0u);
  // back inside: reset accepted -> PAUSED (a session had started), admittance from the measured position
  rig.x = Vec2(0.01, 0.0);
  rig.step();
  rig.command(manip::command_t::FAULT_RESET, 7);
  const ActuatorCommand& c2 = rig.step();
  CHECK(rig.out.results.back().accepted);
  CHECK(rig.ctl.mode() == Mode::kPaused);
  CHECK(c2.send);  // leaving the safe law is also written at once
  CHECK(rig.ctl.admittance().x()[0] == Approx(0.01).margin(1e-6));
  rig.command(manip::command_t::RESUME, 8);
  rig.step();
  CHECK(rig.ctl.mode() == Mode::kRunning);
}

TEST_CASE("controller: drive decimation holds the command between drive ticks", "[controller]") {
  RtConfig cfg;
  Rig rig(cfg);
  int sends = 0;
  for (int i = 0; i < 400; ++i) {
    const ActuatorCommand& c = rig.step([](SensorReading& r) { r.f_sensor_workspace_n = Vec2(1.0, -2.0); });
    sends += c.send;
    CHECK(c.send == (i % 2 == 0));
    CHECK(rig.ctl.last_state().f_motor_n[0] == c.f_motor_n[0]);
  }
  CHECK(sends == 200);
}

TEST_CASE("controller: orderly stop sends zero force for shutdown_cycles, then finishes", "[controller]") {
  RtConfig cfg;
  Rig rig(cfg);
  for (int i = 0; i < 2500; ++i) rig.step();
  rig.ctl.request_stop(StopReason::kRequested);
  const ActuatorCommand& c = rig.step();
  CHECK(rig.ctl.mode() == Mode::kStopped);
  CHECK(c.send);
  CHECK(c.f_motor_n.norm() == 0.0);
  int n = 1;
  while (!rig.ctl.finished()) {
    rig.step();
    ++n;
  }
  CHECK(n == cfg.safety.shutdown_cycles);
  CHECK(static_cast<StopReason>(rig.ctl.status().stop_reason.load()) == StopReason::kRequested);
}
