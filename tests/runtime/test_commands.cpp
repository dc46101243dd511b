// Command validation: ranges/units (bus side), state (loop side), unknown
// kinds, garbage, floods; and the LCM path end to end on memq://.
#include <catch2/catch.hpp>

#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <cmath>
#include <vector>

#include "manip/command_status_t.hpp"
#include "manip/command_t.hpp"
#include "manip/common/channels.hpp"
#include "manip/runtime/bus.hpp"
#include "manip/control/controller.hpp"
#include "manip/runtime/messages.hpp"
#include "manip/trial_event_t.hpp"
#include "../control/memq_rig.hpp"
#include "../control/test_support.hpp"

using manip::Vec2;
using manip::command_t;
using namespace manip::control;
using namespace manip::runtime;

namespace {
command_t make(std::int8_t kind, std::int64_t seq = 1) {
  command_t c{};
  c.utime = 0;
  c.seq = seq;
  c.sender = "test";
  c.kind = kind;
  c.start_shoulder_m[0] = 0.0;
  c.start_shoulder_m[1] = 0.30;
  c.goal_shoulder_m[0] = 0.0;
  c.goal_shoulder_m[1] = 0.55;
  return c;
}
std::vector<std::uint8_t> encode(const command_t& c) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(c.getEncodedSize()));
  c.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}
}  // namespace

TEST_CASE("command validation: kinds, units and ranges", "[commands]") {
  const CommandLimits lim = CommandLimits::from_config(RtConfig{});
  for (std::int8_t k = command_t::START_SESSION; k <= command_t::FAULT_RESET; ++k)
    CHECK(validate_command(make(k), lim) == Reject::kNone);
  CHECK(validate_command(make(0), lim) == Reject::kUnknownKind);
  CHECK(validate_command(make(11), lim) == Reject::kUnknownKind);
  CHECK(validate_command(make(-3), lim) == Reject::kUnknownKind);

  auto t = make(command_t::SET_TARGETS);
  t.goal_shoulder_m[1] = std::nan("");
  CHECK(validate_command(t, lim) == Reject::kNotFinite);
  t = make(command_t::SET_TARGETS);
  t.goal_shoulder_m[1] = 0.56;  // workspace y 0.135 + radius beyond the wall at 0.135
  CHECK(validate_command(t, lim) == Reject::kOutOfWorkspace);
  t = make(command_t::SET_TARGETS);
  t.start_shoulder_m[0] = -0.2;  // 20 cm to the left: outside
  CHECK(validate_command(t, lim) == Reject::kOutOfWorkspace);
  t = make(command_t::SET_TARGETS);
  t.goal_shoulder_m[1] = 0.315;
  CHECK(validate_command(t, lim) == Reject::kTargetsTooClose);
  t = make(command_t::SET_TARGETS);
  t.start_shoulder_m[1] = 0.42;  // trigger 0.40 not between 0.42 and 0.55
  CHECK(validate_command(t, lim) == Reject::kTriggerNotBetweenTargets);
  t = make(command_t::SET_TARGETS);
  t.start_shoulder_m[1] = 0.32;
  t.goal_shoulder_m[0] = 0.05;
  t.goal_shoulder_m[1] = 0.50;
  CHECK(validate_command(t, lim) == Reject::kNone);
  // a non-SET_TARGETS command ignores the target fields (even NaN)
  auto p = make(command_t::PAUSE);
  p.goal_shoulder_m[0] = std::nan("");
  CHECK(validate_command(p, lim) == Reject::kNone);
}

TEST_CASE("command gate: garbage, unknown kind, flood", "[commands]") {
  CommandQueue q(8);
  CommandGate gate(q, CommandLimits::from_config(RtConfig{}));
  SECTION("garbage bytes are answered, never queued") {
    const std::uint8_t junk[] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13};
    auto st = gate.submit(junk, sizeof junk, 0, 2);
    REQUIRE(st);
    CHECK_FALSE(st->accepted);
    CHECK(st->seq == -1);
    CHECK(st->reason.rfind(reject_text(Reject::kUndecodable), 0) == 0);  // + what is wrong, where
    CHECK_FALSE(gate.submit(junk, 0, 0, 2)->accepted);
    // a valid command truncated by one byte
    auto b = encode(make(command_t::PAUSE, 9));
    CHECK(gate.submit(b.data(), static_cast<int>(b.size()) - 1, 0, 2)->seq == -1);
    CHECK(q.size_approx() == 0);
  }
  SECTION("unknown kind names the kind") {
    auto b = encode(make(42, 77));
    auto st = gate.submit(b.data(), static_cast<int>(b.size()), 0, 2);
    REQUIRE(st);
    CHECK(st->seq == 77);
    CHECK(st->kind == 42);
    CHECK(st->reason.find("unknown command kind 42") != std::string::npos);
  }
  SECTION("a flood fills the loop's queue, the rest is rejected as queue full") {
    int queued = 0, full = 0;
    for (int i = 0; i < 1000; ++i) {
      auto b = encode(make(command_t::PERTURBATIONS_ON, i));
      auto st = gate.submit(b.data(), static_cast<int>(b.size()), 0, 2);
      if (!st)
        ++queued;
      else if (st->reason == reject_text(Reject::kQueueFull))
        ++full;
    }
    CHECK(queued >= 8);
    CHECK(queued < 64);
    CHECK(queued + full == 1000);
    CHECK(gate.rejected() == full);
  }
}

namespace {
struct Rig {
  RtConfig cfg;
  RecordQueue log{1 << 16};
  CommandQueue cmds{256};
  Controller ctl;
  test_support::Drained out;
  std::int64_t k{0};
  Vec2 x{Vec2::Zero()};
  explicit Rig(const RtConfig& c) : cfg(c), ctl(c, {&log, nullptr, &cmds}, ControllerOptions{false, false, 0, 0}) {}
  void step() {
    ctl.step(test_support::reading(k, x), k);  // the handle stays where the test puts it
    ++k;
    test_support::drain(log, out);
  }
  CommandResultRecord send(std::int8_t kind, const Vec2& start = Vec2(0.0, 0.30), const Vec2& goal = Vec2(0.0, 0.55)) {
    Command c;
    c.kind = kind;
    c.seq = k + 1000;
    c.start_shoulder_m = start;
    c.goal_shoulder_m = goal;
    REQUIRE(cmds.try_push(c));
    const std::size_t before = out.results.size();
    step();
    REQUIRE(out.results.size() == before + 1);
    CHECK(out.results.back().seq == c.seq);
    return out.results.back();
  }
};
RtConfig manual_start() {
  RtConfig c;
  c.protocol.autostart = false;
  c.safety.max_tracking_error_m = 10.0;  // scripted handle positions
  c.safety.max_motor_force_n = 1e12;
  return c;
}
}  // namespace

TEST_CASE("commands: allowed only in the modes the table says", "[commands][controller]") {
  Rig r(manual_start());
  r.step();
  REQUIRE(r.ctl.mode() == Mode::kIdle);
  CHECK(r.send(command_t::PAUSE).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::RESUME).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::NEXT_TRIAL).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::FAULT_RESET).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::SET_TARGETS, Vec2(0.0, 0.32), Vec2(0.0, 0.52)).accepted);  // idle: allowed
  CHECK(r.ctl.protocol().goal_shoulder_m()[1] == Approx(0.52));
  CHECK(r.send(command_t::SET_TARGETS).accepted);  // back to the defaults
  CHECK(r.send(command_t::PERTURBATIONS_OFF).accepted);
  CHECK_FALSE(r.ctl.protocol().perturbations_enabled());
  CHECK(r.send(command_t::PERTURBATIONS_ON).accepted);
  CHECK(r.send(command_t::START_SESSION).accepted);
  CHECK(r.ctl.mode() == Mode::kRunning);
  CHECK(r.send(command_t::START_SESSION).reason == Reject::kSessionAlreadyStarted);
  // hand at the workspace origin = (0, 0.425) shoulder: not in the start target
  CHECK(r.send(command_t::NEXT_TRIAL).reason == Reject::kHandNotInStart);
  // move the handle into the start target and start at once with NEXT_TRIAL
  r.x = r.cfg.session.frame.point_to_workspace(r.cfg.protocol.start_shoulder_m);
  r.step();
  const auto res = r.send(command_t::NEXT_TRIAL);
  CHECK(res.accepted);
  CHECK(r.ctl.protocol().trial_active());
  CHECK(r.out.events.back().kind == manip::trial_event_t::START);
  CHECK(r.send(command_t::SET_TARGETS).reason == Reject::kTrialActive);
  // NEXT_TRIAL during a trial aborts it
  CHECK(r.send(command_t::NEXT_TRIAL).accepted);
  CHECK(r.out.events.back().kind == manip::trial_event_t::ABORT);
  CHECK(r.out.events.back().reason == AbortReason::kOperatorNext);
  CHECK(r.send(command_t::PAUSE).accepted);
  CHECK(r.ctl.mode() == Mode::kPaused);
  CHECK(r.send(command_t::START_SESSION).reason == Reject::kSessionAlreadyStarted);
  CHECK(r.send(command_t::RESUME).accepted);
  CHECK(r.send(command_t::STOP_SESSION).accepted);
  CHECK(r.ctl.mode() == Mode::kDone);
  CHECK(r.send(command_t::START_SESSION).reason == Reject::kSessionDone);
  CHECK(r.send(command_t::STOP_SESSION).reason == Reject::kSessionDone);
  // in a fault only ESTOP and FAULT_RESET act
  r.send(command_t::ESTOP);
  CHECK(r.ctl.mode() == Mode::kEStop);
  CHECK(r.send(command_t::RESUME).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::PERTURBATIONS_ON).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::SET_TARGETS).reason == Reject::kNotAllowedInMode);
  CHECK(r.send(command_t::ESTOP).accepted);
  // every result went out with a text for the status channel
  const auto st = to_message(r.out.results.back());
  CHECK(st.accepted);
  const auto rej = to_message(r.out.results[r.out.results.size() - 2]);
  CHECK(rej.reason.find("not allowed") != std::string::npos);
  CHECK(rej.reason.find("ESTOP") != std::string::npos);
}

TEST_CASE("commands: a flood is taken at most max_commands_per_cycle per cycle", "[commands][controller]") {
  Rig r(manual_start());
  r.step();
  for (int i = 0; i < 200; ++i) {
    Command c;
    c.kind = command_t::PERTURBATIONS_ON;
    c.seq = i;
    REQUIRE(r.cmds.try_push(c));
  }
  std::size_t prev = r.out.results.size();
  int cycles = 0;
  while (r.cmds.size_approx() > 0) {
    r.step();
    ++cycles;
    CHECK(r.out.results.size() - prev <= static_cast<std::size_t>(r.cfg.cycle.max_commands_per_cycle));
    prev = r.out.results.size();
  }
  CHECK(cycles == 200 / r.cfg.cycle.max_commands_per_cycle);
  CHECK(r.ctl.mode() == Mode::kIdle);
}

TEST_CASE("bus: commands over LCM (memq), garbage and statuses", "[commands][bus]") {
#if defined(__SANITIZE_ADDRESS__)
  // LCM 1.3.1's dispatch hands typed C++ subscriptions a corrupt user-data
  // pointer in sanitizer builds (reproduced with a 5-line memq program, not
  // specific to manip): checked in the Release run only.
  WARN("skipped under sanitizers (LCM memq dispatch + UBSan)");
  return;
#endif
  RtConfig cfg = manual_start();
  test_support::MemqRig rig(cfg);
  auto& ctl = rig.ctl;
  auto& bus = rig.bus;
  std::vector<manip::command_status_t> statuses;
  rig.collect(manip::channels::kCommandStatus, statuses);

  const std::uint8_t junk[] = {0xde, 0xad, 0xbe, 0xef, 0x00, 0x11};
  bus.lcm()->publish(manip::channels::kCommand, junk, sizeof junk);
  auto start = make(command_t::START_SESSION, 11);
  bus.lcm()->publish(manip::channels::kCommand, &start);
  auto bad = make(command_t::SET_TARGETS, 12);
  bad.goal_shoulder_m[1] = 0.9;
  bus.lcm()->publish(manip::channels::kCommand, &bad);
  ctl.step(test_support::reading(0, Vec2::Zero()), 0);  // INIT -> IDLE before the commands arrive
  for (int i = 0; i < 20; ++i) bus.poll(0);  // deliver to the bus (rejections answered here)
  for (std::int64_t k = 1; k < 4; ++k) ctl.step(test_support::reading(k, Vec2::Zero()), k);  // loop answers START
  for (int i = 0; i < 20; ++i) bus.poll(0);
  REQUIRE(statuses.size() >= 3);
  bool garbage = false, started = false, out_of_ws = false;
  for (const auto& s : statuses) {
    garbage |= s.seq == -1 && !s.accepted;
    started |= s.seq == 11 && s.accepted && s.mode == static_cast<int>(Mode::kRunning);
    out_of_ws |= s.seq == 12 && !s.accepted && s.reason == reject_text(Reject::kOutOfWorkspace);
  }
  CHECK(garbage);
  CHECK(started);
  CHECK(out_of_ws);
  CHECK(ctl.mode() == Mode::kRunning);
  CHECK(bus.published_states() >= 1);
}
