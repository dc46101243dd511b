#pragma once
// A CanDriveSet on a VirtualRig with a frame recorder: the harness of the
// start-up, fault and closed-loop tests.
#include <catch2/catch.hpp>

#include <vector>

#include "manip/canopen/can_check.hpp"
#include "rig.hpp"

namespace canopen_test {

using namespace manip::canopen;

struct Sent {
  int64_t t_us;
  std::size_t bus;
  int sender;  // 0 = master endpoint
  CanFrame f;
};

struct Session {
  CanConfig cfg;
  VirtualRig rig;
  CanDriveSet set;
  std::vector<Sent> sent;
  bool record = true;

  explicit Session(const char* yaml, const std::function<void(SimDriveParams&)>& tweak = {})
      : Session(parse_ok(yaml), tweak) {}
  Session(const CanConfig& c, const std::function<void(SimDriveParams&)>& tweak = {})
      : cfg(c), rig(cfg, 250, tweak), set(cfg, rig.master_ports()) {
    sent.reserve(1 << 17);
    for (std::size_t b = 0; b < rig.bus_count(); ++b)
      rig.bus(b).set_tap([this, b](int64_t t, int sender, const CanFrame& f) {
        if (record) sent.push_back({t, b, sender, f});
      });
  }
  CanDriveSet::Ticker ticker() {
    return [this] { return rig.tick(); };
  }
  Error configure() { return set.configure(ticker()); }
  Error enable() { return set.enable(ticker()); }
  // One 4 kHz control cycle: drives run, then read -> (controller) -> write.
  const DriveSetFeedback& cycle(const manip::Vec2& force_n = manip::Vec2::Zero()) {
    const int64_t now = rig.tick();
    const auto& fb = set.read(now);
    set.write(force_n);
    return fb;
  }
  void start() {
    const Error e = configure();
    INFO(describe(e));
    REQUIRE_FALSE(e);
    const Error e2 = enable();
    INFO(describe(e2));
    REQUIRE_FALSE(e2);
  }
  // Cycles until the set reports a fault (or max); returns the cycles run, -1 if none.
  int run_until_fault(int max_cycles) {
    for (int i = 1; i <= max_cycles; ++i) {
      cycle();
      if (set.faulted()) return i;
    }
    return -1;
  }
  // Frames the master sent at time t on bus b.
  std::vector<CanFrame> master_frames_at(int64_t t, std::size_t b) const {
    std::vector<CanFrame> v;
    for (const auto& s : sent)
      if (s.t_us == t && s.bus == b && s.sender == 0) v.push_back(s.f);
    return v;
  }
  std::size_t count_master(std::size_t b, uint32_t lo, uint32_t hi, int64_t from_us = 0) const {
    std::size_t n = 0;
    for (const auto& s : sent)
      if (s.bus == b && s.sender == 0 && s.f.id >= lo && s.f.id <= hi && s.t_us >= from_us) ++n;
    return n;
  }
  // The safe state of the issue: the fault cycle itself sent, on every bus,
  // the RPDOs with Disable voltage + zero torque followed by a SYNC; the
  // drives act on them once they are off the wire (~265 us at 1 Mbit/s
  // behind a TPDO), i.e. no later than the drive step 500 us later: then no
  // drive is enabled or applies force.
  void check_safe_state_after_fault() {
    const int64_t t = rig.now();
    for (std::size_t b = 0; b < rig.bus_count(); ++b) {
      const auto fr = master_frames_at(t, b);
      bool rpdo_safe = false, sync_after = false;
      for (const auto& f : fr) {
        if ((f.id & 0x780) == 0x200 && f.dlc == 4) rpdo_safe = f.data[0] == 0 && f.data[1] == 0 && f.data[2] == 0 && f.data[3] == 0;
        if (f.id == 0x080 && rpdo_safe) sync_after = true;
      }
      INFO("bus " << b);
      CHECK(rpdo_safe);
      CHECK(sync_after);
    }
    rig.tick();
    rig.tick();  // the drives have processed that SYNC
    for (std::size_t i = 0; i < rig.drive_count(); ++i) {
      INFO("drive " << i);
      CHECK(rig.drive(i).state() != cia402::State::OperationEnabled);
      CHECK(rig.drive(i).applied_force_n() == 0.0);
    }
  }
};

}  // namespace canopen_test
