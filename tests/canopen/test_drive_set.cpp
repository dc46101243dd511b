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
