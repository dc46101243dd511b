// The CanDriveSet facade: lifecycle, a closed loop on the simulated moving
// masses, shutdown, and the allocation-free cyclic path.
#include <catch2/catch.hpp>

#include <atomic>
#include <cstdlib>
#include <new>

#include "session.hpp"

// Counting global operator new (test-local; a shared one will come later).
// Every form is replaced so new/delete pairs stay consistent (ASan checks).
namespace {
std::atomic<long> g_allocations{0};
std::atomic<bool> g_counting{false};
void* counted_alloc(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* counted_alloc_aligned(std::size_t n, std::align_val_t a) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  const std::size_t al = static_cast<std::size_t>(a);
  if (void* p = std::aligned_alloc(al, (n + al - 1) / al * al)) return p;
  throw std::bad_alloc();
}
}  // namespace
void* operator new(std::size_t n) { return counted_alloc(n); }
void* operator new[](std::size_t n) { return counted_alloc(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t a) { return counted_alloc_aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counted_alloc_aligned(n, a); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }

using namespace canopen_test;
using namespace manip::canopen;
using manip::Vec2;

namespace {
// PD hold on the workspace frame, the shape of the real backend loop.
Vec2 pd(const DriveSetFeedback& fb, const Vec2& ref, double kp, double kd) {
  return -kp * (fb.position_m - ref) - kd * fb.velocity_mps;
}
}  // namespace

TEST_CASE("canopen drive set: PD holds position against external forces, signs and axis mapping (two buses)") {
  Session s(kTwoBuses);
  s.start();
  // Drive frame: 5 N on stage_x (+x1), -3 N on stage_y (sign -1: that is +3 N along workspace x2).
  s.rig.drive(0).set_external_force(5.0);
  s.rig.drive(1).set_external_force(-3.0);
  const double kp = 2000, kd = 60;
  DriveSetFeedback fb = s.cycle();
  for (int i = 0; i < 8000; ++i) {  // 2 s
    fb = s.cycle(pd(fb, Vec2::Zero(), kp, kd));
  }
  CHECK_FALSE(s.set.faulted());
  // Steady state by hand: x = F_ext / Kp (Coulomb friction 0.5 N: +-0.25 mm).
  CHECK(fb.position_m.x() == Approx(5.0 / kp).margin(0.0003));
  CHECK(fb.position_m.y() == Approx(3.0 / kp).margin(0.0003));
  CHECK(s.rig.drive(1).position_m() == Approx(-3.0 / kp).margin(0.0003));  // drive frame
  CHECK(std::abs(fb.velocity_mps.x()) < 1e-3);
  // Move the reference: reaches 50 mm within 1 s.
  const Vec2 ref(0.05, -0.02);
  for (int i = 0; i < 4000; ++i) fb = s.cycle(pd(fb, ref, kp, kd));
  CHECK(fb.position_m.x() == Approx(0.05 + 5.0 / kp).margin(0.0005));
  CHECK(fb.position_m.y() == Approx(-0.02 + 3.0 / kp).margin(0.0005));
  CHECK(s.rig.drive(0).position_m() == Approx(fb.position_m.x()).margin(2e-5));
  CHECK(s.rig.drive(1).position_m() == Approx(-fb.position_m.y()).margin(2e-5));

  // disable -> shutdown: drives disabled, pre-operational, heartbeat consumer off.
  CHECK_FALSE(s.set.disable(s.ticker()));
  CHECK(s.rig.drive(0).state() == cia402::State::SwitchOnDisabled);
  CHECK_FALSE(s.set.shutdown(s.ticker()));
  CHECK(s.set.master(0).phase() == Phase::Stopped);
  CHECK(s.rig.drive(0).nmt_state() == NmtState::PreOperational);
  CHECK(s.rig.drive(1).od_value(0x1016, 1) == 0u);
  for (int i = 0; i < 2000; ++i) s.rig.tick();  // no heartbeat EMCY: consumer was switched off first
  CHECK(s.rig.drive(0).state() == cia402::State::SwitchOnDisabled);
}

TEST_CASE("canopen drive set: shared bus at 1 kHz, PD hold") {
  Session s(kSharedBus);
  s.start();
  s.rig.drive(1).set_external_force(4.0);
  DriveSetFeedback fb = s.cycle();
  for (int i = 0; i < 8000; ++i) fb = s.cycle(pd(fb, Vec2::Zero(), 1500, 50));
  CHECK_FALSE(s.set.faulted());
  CHECK(fb.position_m.y() == Approx(4.0 / 1500).margin(0.0004));
  CHECK(fb.position_m.x() == Approx(0.0).margin(0.0002));
  CHECK(s.set.master(0).syncs_sent() > 8000u / 4 - 10);
}

TEST_CASE("canopen drive set: event status register read after a fault at shutdown") {
  Session s(kTwoBuses);
  s.start();
  s.rig.drive(0).enter_fault(0x2310, (1u << 0) | (1u << 22));
  REQUIRE(s.run_until_fault(10) > 0);
  const Error e = s.set.shutdown(s.ticker());
  CHECK(e.code != ErrorCode::None);  // shutdown reports why the session ended
  const NodeIdentity& id = s.set.master(0).node(0).identity;
  CHECK(id.event_status_read);
  CHECK(id.event_status == ((1u << 0) | (1u << 22)));
  CHECK(copley_event_status_text(id.event_status) == "short circuit detected, drive fault (latched)");
}

TEST_CASE("canopen drive set: the cyclic path does not allocate (10000 cycles)") {
  Session s(kTwoBuses);
  s.record = false;
  s.start();
  DriveSetFeedback fb = s.cycle();
  for (int i = 0; i < 100; ++i) fb = s.cycle(pd(fb, Vec2::Zero(), 2000, 60));
  g_allocations = 0;
  g_counting = true;
  for (int i = 0; i < 10000; ++i) fb = s.cycle(pd(fb, Vec2(0.01, 0.0), 2000, 60));
  g_counting = false;
  CHECK(g_allocations.load() == 0);
  CHECK_FALSE(s.set.faulted());
  // and the counter works: a fault path that formats text does allocate
  g_counting = true;
  const std::string text = describe(Error{ErrorCode::HeartbeatLost, 1, 0, 0, 0, 150, 0});
  g_counting = false;
  CHECK(g_allocations.load() > 0);
  CHECK(text == "node 1: heartbeat lost (after 150 ms)");
}

// An e-stop / STO that drops a drive out of Operation enabled without a
// CANopen fault (0x6041 bit 4 off; the drive falls to Switch on disabled or
// Ready to switch on, or stays in Operation enabled without power): the
// master faults the bus (UncommandedDisable, safe state on every bus, both
// axes) and nothing re-enables when the power returns, only an operator
// reset (IEC 60204-1, emergency stop). Before this, write() kept walking the
// drive back through transitions 2-3-4 by itself.
TEST_CASE("canopen drive set: a drive leaving Operation enabled by itself disarms both drives until the reset") {
  Session s(kTwoBuses);
  s.record = true;
  s.start();
  DriveSetFeedback fb = s.cycle();
  for (int i = 0; i < 200; ++i) fb = s.cycle(pd(fb, Vec2::Zero(), 2000, 60));
  REQUIRE(fb.enabled);
  cia402::State falls_to = cia402::State::SwitchOnDisabled;
  SECTION("falls to Switch on disabled") { falls_to = cia402::State::SwitchOnDisabled; }
  SECTION("falls to Ready to switch on") { falls_to = cia402::State::ReadyToSwitchOn; }
  SECTION("stays in Operation enabled with bit 4 off") { falls_to = cia402::State::OperationEnabled; }
  INFO(cia402::to_string(falls_to));
  SimulatedDrive& d = s.rig.drive(0);
  d.faults().power_loss_state = falls_to;
  d.faults().power_stage_lost = true;
  const int n = s.run_until_fault(8);
  REQUIRE(n > 0);
  CHECK(s.set.error().code == ErrorCode::UncommandedDisable);
  CHECK(s.set.error().node == d.node_id());
  CHECK((s.set.error().value & cia402::sw::kVoltageEnabled) == 0);
  CHECK(describe(s.set.error()).find("left Operation enabled without a command") != std::string::npos);
  CHECK(s.set.fault_acknowledgeable());
  s.check_safe_state_after_fault();  // both buses: Disable voltage + zero torque + SYNC, both drives off
  d.faults().power_stage_lost = false;  // power back
  int op = 0, torque = 0;
  for (int i = 0; i < 4000; ++i) {  // 1 s, the controller still asking for force
    fb = s.cycle(Vec2(5.0, -5.0));
    for (std::size_t k = 0; k < s.rig.drive_count(); ++k) {
      op += s.rig.drive(k).state() == cia402::State::OperationEnabled;
      torque += s.rig.drive(k).target_torque_permille() != 0;
    }
  }
  CHECK(op == 0);
  CHECK(torque == 0);
  CHECK(s.set.faulted());
  CHECK_FALSE(s.set.enable_wanted());
  // The operator's reset: back to cyclic (no drive in Fault: no edge needed),
  // then the real-time enable walks 2-3-4 with zero torque preloaded.
  REQUIRE(s.set.request_fault_reset());
  int k = 0;
  while (s.set.faulted() && k++ < 100) fb = s.cycle();
  REQUIRE_FALSE(s.set.faulted());
  CHECK(d.fault_resets() == 0);  // it was never in Fault: no bit-7 edge was sent
  s.set.request_enable();
  k = 0;
  while (!fb.enabled && k++ < 2000) fb = s.cycle();
  INFO("cycles to Operation enabled: " << k);
  REQUIRE(fb.enabled);
  // A commanded disable (transition 9) is not a departure.
  CHECK_FALSE(s.set.disable(s.ticker()));
  CHECK_FALSE(s.set.faulted());
}

TEST_CASE("canopen drive set: an enable that cannot complete can be cancelled and never completes later") {
  Session s(kTwoBuses);
  s.start();
  DriveSetFeedback fb = s.cycle();
  CHECK_FALSE(s.set.disable(s.ticker()));
  SimulatedDrive& d = s.rig.drive(1);
  d.faults().power_stage_lost = true;  // transition 3 needs the power stage
  s.set.request_enable();
  for (int i = 0; i < 400; ++i) fb = s.cycle();
  CHECK_FALSE(fb.enabled);
  CHECK(d.state() != cia402::State::OperationEnabled);
  CHECK(s.rig.drive(0).state() == cia402::State::OperationEnabled);  // the powered one got there
  s.set.cancel_enable();
  for (int i = 0; i < 4; ++i) fb = s.cycle();  // commanded Disable voltage (transition 9): not a departure
  d.faults().power_stage_lost = false;
  for (int i = 0; i < 4000; ++i) {
    fb = s.cycle(Vec2(5.0, 5.0));
    REQUIRE(s.rig.drive(0).state() != cia402::State::OperationEnabled);
    REQUIRE(d.state() != cia402::State::OperationEnabled);
  }
  CHECK_FALSE(s.set.faulted());
}
