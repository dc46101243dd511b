// Start-up, cyclic phase and every fault of the checklist over the
// in-process virtual bus with simulated drives and simulated time.
#include <catch2/catch.hpp>

#include <linux/can.h>
#include <linux/can/error.h>

#include "session.hpp"

using namespace canopen_test;
using namespace manip::canopen;
using manip::Vec2;

TEST_CASE("canopen session: start-up remaps in pre-operational, exactly the CiA 301 sequence, and reads back") {
  Session s(kTwoBuses);
  // Record the drive's NMT state whenever the master writes a mapping object.
  std::vector<NmtState> nmt_at_remap;
  s.rig.bus(0).set_tap([&](int64_t t, int sender, const CanFrame& f) {
    s.sent.push_back({t, 0, sender, f});
    if (sender == 0 && f.id == 0x601 && (f.data[0] & 0xE0) == 0x20 && f.data[2] == 0x16)
      nmt_at_remap.push_back(s.rig.drive(0).nmt_state());
  });
  const Error e = s.configure();
  INFO(describe(e));
  REQUIRE_FALSE(e);
  REQUIRE_FALSE(nmt_at_remap.empty());
  for (auto st : nmt_at_remap) CHECK(st == NmtState::PreOperational);

  // The RPDO1 remap requests, written out by hand from CiA 301 §7.4.8.2:
  std::vector<CanFrame> expected = {
      make_frame(0x601, {0x23, 0x00, 0x14, 0x01, 0x01, 0x02, 0x00, 0x80}),  // 0x1400:01 = 0x80000201 (invalid)
      make_frame(0x601, {0x2F, 0x00, 0x16, 0x00, 0x00, 0, 0, 0}),           // 0x1600:00 = 0
      make_frame(0x601, {0x23, 0x00, 0x16, 0x01, 0x10, 0x00, 0x40, 0x60}),  // 0x1600:01 = 0x60400010
      make_frame(0x601, {0x23, 0x00, 0x16, 0x02, 0x10, 0x00, 0x71, 0x60}),  // 0x1600:02 = 0x60710010
      make_frame(0x601, {0x2F, 0x00, 0x16, 0x00, 0x02, 0, 0, 0}),           // 0x1600:00 = 2
      make_frame(0x601, {0x2F, 0x00, 0x14, 0x02, 0x01, 0, 0, 0}),           // 0x1400:02 = 1 (every SYNC)
      make_frame(0x601, {0x23, 0x00, 0x14, 0x01, 0x01, 0x02, 0x00, 0x00}),  // 0x1400:01 = 0x201 (valid)
      make_frame(0x601, {0x40, 0x00, 0x16, 0x00, 0, 0, 0, 0}),              // read back 0x1600:00
  };
  std::vector<CanFrame> sdo;
  for (const auto& x : s.sent)
    if (x.bus == 0 && x.sender == 0 && x.f.id == 0x601) sdo.push_back(x.f);
  auto it = std::search(sdo.begin(), sdo.end(), expected.begin(), expected.end());
  CHECK(it != sdo.end());

  SimulatedDrive& d = s.rig.drive(0);
  CHECK(d.nmt_state() == NmtState::Operational);
  CHECK(d.od_value(0x1016, 1) == 0x007F0064u);  // consumer of node 127, 100 ms
  CHECK(d.od_value(0x1017, 0) == 50u);
  CHECK(d.od_value(0x1006, 0) == 500u);
  CHECK(d.od_value(0x60C2, 1) == 5u);  // 5 * 10^-4 s
  CHECK(d.od_value(0x60C2, 2) == 0xFCu);
  CHECK(d.od_value(0x6060, 0) == 10u);
  CHECK(d.od_value(0x1801, 1) == 0x80000281u);  // factory-valid TPDO2 disabled
  CHECK(d.od_value(0x1A00, 2) == 0x60640020u);
  CHECK(d.state() == cia402::State::SwitchOnDisabled);  // configured, not enabled
  const NodeIdentity& id = s.set.master(0).node(0).identity;
  CHECK(id.vendor_id == 0xABu);
  CHECK(id.device_type == 0x00020192u);
  CHECK(std::string(id.name.data()) == "manip simulated CiA 402 drive");  // segmented upload
  CHECK(id.rated_current_ma == 5000u);
}

TEST_CASE("canopen session: enable preloads zero torque - 10000 cycles: 2 kHz SYNC, every TPDO, no SDO") {
  Session s(kTwoBuses);
  REQUIRE_FALSE(s.configure());
  const int64_t t_cyclic = s.rig.now();
  REQUIRE_FALSE(s.enable());
  // The first RPDO carrying Enable operation (0x0F) carries zero torque.
  bool found = false;
  for (const auto& x : s.sent)
    if (x.sender == 0 && x.f.id == 0x201 && x.f.data[0] == 0x0F) {
      CHECK(x.f.data[2] == 0);
      CHECK(x.f.data[3] == 0);
      found = true;
      break;
    }
  CHECK(found);
  const uint32_t sync0 = s.set.master(0).syncs_sent();
  const uint32_t tp0 = s.set.master(0).node(0).tpdo_received;
  for (int i = 0; i < 10000; ++i) s.cycle(Vec2(1.0, -1.0));
  CHECK_FALSE(s.set.faulted());
  CHECK(s.set.master(0).syncs_sent() - sync0 == 5000u);                 // 10000 * 250 us / 500 us
  CHECK(s.set.master(0).node(0).tpdo_received - tp0 >= 4999u);
  CHECK(s.set.master(1).node(0).tpdo_missed_total == 0u);
  CHECK(s.count_master(0, 0x600, 0x67F, t_cyclic) == 0u);                 // no SDO in the cyclic phase
  CHECK(s.count_master(1, 0x600, 0x67F, t_cyclic) == 0u);
  CHECK(s.set.master(0).request_sdo(1, 0x1002, 0).code == ErrorCode::SdoNotAllowed);
  CHECK(s.rig.drive(0).state() == cia402::State::OperationEnabled);
  CHECK(s.rig.drive(0).applied_force_n() == Approx(1.0));   // 10 per mille of 100 N
  CHECK(s.rig.drive(1).applied_force_n() == Approx(1.0));   // sign -1: workspace -1 N = drive +1 N
}

TEST_CASE("canopen fault: k consecutive missing TPDOs") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 100; ++i) s.cycle();
  s.rig.drive(0).faults().drop_all_tpdos = true;
  const int n = s.run_until_fault(100);
  // tpdo_miss_limit = 3 SYNC periods of 2 cycles, plus the TPDO already on its way
  CHECK(n > 0);
  CHECK(n <= 3 * 2 + 4);
  CHECK(s.set.error().code == ErrorCode::TpdoMissing);
  CHECK(describe(s.set.error()) == "node 1: TPDOs missing for consecutive SYNC periods (3 consecutive periods)");
  s.check_safe_state_after_fault();
}

TEST_CASE("canopen fault: EMCY that faults the session and EMCY that is only logged") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 40; ++i) s.cycle();
  s.rig.drive(1).inject_emcy(0x4210, 0x09, false);  // device temperature: warning
  for (int i = 0; i < 40; ++i) s.cycle();
  CHECK_FALSE(s.set.faulted());
  bool logged = false;
  for (std::size_t i = 0; i < s.set.master(1).log_count(); ++i)
    logged |= s.set.master(1).log_entry(i).code == ErrorCode::EmcyWarning && s.set.master(1).log_entry(i).value == 0x4210;
  CHECK(logged);
  s.rig.drive(1).inject_emcy(0x2310, 0x03, false);  // over-current: faults the session
  const int n = s.run_until_fault(10);
  CHECK(n > 0);
  CHECK(n <= 2);
  CHECK(s.set.error().code == ErrorCode::EmcyFault);
  CHECK(describe(s.set.error()) ==
        "node 1: EMCY (faults the session) code 0x2310 (current (over-current / short circuit)), error register 0x03");
  s.check_safe_state_after_fault();
}

TEST_CASE("canopen fault: drive in Fault state (its EMCY lost on the bus)") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 40; ++i) s.cycle();
  s.rig.bus(0).set_injector([](int, const CanFrame& f) { return VirtualBus::Injection{f.id == 0x081, 0}; });
  s.rig.drive(0).enter_fault(0x7305, 1u << 5);
  const int n = s.run_until_fault(10);
  CHECK(n > 0);
  CHECK(n <= 3);
  CHECK(s.set.error().code == ErrorCode::DriveFault);
  CHECK(describe(s.set.error()).find("drive in CiA 402 Fault (statusword 0x02") != std::string::npos);
  s.check_safe_state_after_fault();
}

TEST_CASE("canopen fault: heartbeat loss") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 40; ++i) s.cycle();
  const int64_t t0 = s.rig.now();
  s.rig.drive(1).faults().heartbeat_stopped = true;
  const int n = s.run_until_fault(2000);
  REQUIRE(n > 0);
  // timeout 150 ms after the last heartbeat (sent at most 50 ms before t0)
  CHECK(s.rig.now() - t0 >= 100000);
  CHECK(s.rig.now() - t0 <= 150000 + 250);
  CHECK(s.set.error().code == ErrorCode::HeartbeatLost);
  CHECK(s.set.error().node == 1);
  s.check_safe_state_after_fault();
  for (int i = 0; i < 1000; ++i) s.cycle();  // reported once, not every cycle
  int reports = 0;
  for (std::size_t i = 0; i < s.set.master(1).log_count(); ++i)
    reports += s.set.master(1).log_entry(i).code == ErrorCode::HeartbeatLost;
  CHECK(reports == 1);
}

TEST_CASE("canopen fault: bus-off on one bus stops both buses in the same cycle") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 40; ++i) s.cycle();
  CanFrame e;
  e.id = CAN_ERR_BUSOFF;
  e.dlc = 8;
  s.rig.bus(1).inject_error_frame(e);
  CHECK(s.run_until_fault(1) == 1);
  CHECK(s.set.error().code == ErrorCode::BusOff);
  CHECK(s.set.master(0).phase() == Phase::Faulted);
  CHECK(s.set.master(1).phase() == Phase::Faulted);
  CHECK(describe(s.set.error()) == "bus: CAN controller bus-off");
  s.check_safe_state_after_fault();
}

TEST_CASE("canopen start-up failures: clear error, nothing enabled") {
  Session s(kTwoBuses);
  std::string expect;
  ErrorCode code = ErrorCode::None;
  SECTION("a drive that never boots (boot deadline)") {
    s.rig.drive(1).faults().never_boot = true;
    code = ErrorCode::BootTimeout;
    expect = "node 1: node never booted (no boot-up/heartbeat before the boot deadline) (after 200 ms)";
  }
  SECTION("a wrong node answers") {
    s.rig.drive(0).faults().answer_as_node = 5;
    code = ErrorCode::UnexpectedNode;
    expect = "node 5: frame from an unexpected node id (COB-ID 0x585; configured node expected: 1)";
  }
  SECTION("SDO abort") {
    s.rig.drive(0).faults().reject_index = 0x6060;
    s.rig.drive(0).faults().reject_abort = 0x06090030;
    code = ErrorCode::SdoAbort;
    expect = "node 1: SDO aborted by the drive at 0x6060:00, abort code 0x06090030 (invalid value for parameter (download only))";
  }
  SECTION("SDO timeout") {
    s.rig.drive(0).faults().sdo_silent = true;
    code = ErrorCode::SdoTimeout;
    expect = "node 1: SDO timeout (no answer) at 0x1000:00";
  }
  SECTION("rated current differs from the config") {
    s.cfg.drives[1].rated_current_a = 4.0;
    s.set = CanDriveSet(s.cfg, s.rig.master_ports());
    code = ErrorCode::VerifyMismatch;
    expect = "node 1: read-back differs from the configuration at 0x6075:00: read 0x00001388, expected 0x00000FA0";
  }
  const Error e = s.configure();
  CHECK(e.code == code);
  CHECK(describe(e) == expect);
  CHECK(s.set.faulted());
  // Nothing enabled: no RPDO with a controlword or torque other than zero
  // (the healthy bus may already have been cyclic with Disable voltage).
  std::size_t nonzero = 0;
  for (const auto& x : s.sent)
    if (x.sender == 0 && (x.f.id & 0x780) == 0x200 && (x.f.data[0] | x.f.data[1] | x.f.data[2] | x.f.data[3])) ++nonzero;
  CHECK(nonzero == 0u);
  CHECK(s.enable().code != ErrorCode::None);     // enabling is refused
  for (std::size_t i = 0; i < s.rig.drive_count(); ++i)
    CHECK(s.rig.drive(i).state() != cia402::State::OperationEnabled);
}

TEST_CASE("canopen: re-initialisation after an e-stop power cycle of a drive") {
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 40; ++i) s.cycle();
  s.rig.drive(0).power_cycle(s.rig.now(), 100000);  // e-stop: 100 ms without power
  const int n = s.run_until_fault(4000);
  REQUIRE(n > 0);
  // Without power the TPDOs stop first (3 SYNC periods); the boot-up comes
  // 120 ms later and is logged; the lost configuration forbids a mere reset.
  CHECK(s.set.error().code == ErrorCode::TpdoMissing);
  for (int i = 0; i < 1000; ++i) s.cycle();
  bool rebooted = false;
  for (std::size_t i = 0; i < s.set.master(0).log_count(); ++i)
    rebooted |= s.set.master(0).log_entry(i).code == ErrorCode::NodeRebooted;
  CHECK(rebooted);
  CHECK(s.set.request_fault_reset() == false);
  const Error e = s.configure();
  INFO(describe(e));
  CHECK_FALSE(e);
  CHECK_FALSE(s.enable());
  for (int i = 0; i < 100; ++i) s.cycle(Vec2(2.0, 0.0));
  CHECK_FALSE(s.set.faulted());
  CHECK(s.rig.drive(0).applied_force_n() == Approx(2.0));
}

TEST_CASE("canopen: heartbeat monitoring is not latched across a reconnect") {
  Session s(kTwoBuses);
  s.start();
  s.rig.drive(0).power_cycle(s.rig.now(), 2000000);  // off 2 s: heartbeat lost first
  REQUIRE(s.run_until_fault(4000) > 0);
  CHECK(s.set.error().code == ErrorCode::TpdoMissing);
  for (int i = 0; i < 12000; ++i) s.cycle();  // the drive is back
  bool lost = false;
  for (std::size_t i = 0; i < s.set.master(0).log_count(); ++i)
    lost |= s.set.master(0).log_entry(i).code == ErrorCode::HeartbeatLost;
  CHECK(lost);
  CHECK(s.set.request_fault_reset() == false);
  REQUIRE_FALSE(s.configure());
  REQUIRE_FALSE(s.enable());
  for (int i = 0; i < 2000; ++i) s.cycle();
  CHECK_FALSE(s.set.faulted());  // not latched "lost"
  s.rig.drive(0).faults().heartbeat_stopped = true;
  REQUIRE(s.run_until_fault(2000) > 0);  // not latched "ok" either
  CHECK(s.set.error().code == ErrorCode::HeartbeatLost);
}

TEST_CASE("canopen: fault reset only on operator request and as a rising edge of bit 7") {
  Session s(kTwoBuses);
  s.start();
  s.rig.drive(0).enter_fault(0x7305, 0);
  REQUIRE(s.run_until_fault(10) > 0);
  const std::size_t mark = s.sent.size();
  for (int i = 0; i < 400; ++i) s.cycle();
  for (std::size_t i = mark; i < s.sent.size(); ++i)
    if (s.sent[i].sender == 0 && s.sent[i].f.id == 0x201) CHECK((s.sent[i].f.data[0] & 0x80) == 0);
  CHECK(s.rig.drive(0).state() == cia402::State::Fault);  // never reset by itself
  CHECK(s.set.request_fault_reset());
  for (int i = 0; i < 20; ++i) s.cycle();
  std::vector<uint16_t> cws;
  for (std::size_t i = mark; i < s.sent.size(); ++i)
    if (s.sent[i].sender == 0 && s.sent[i].f.id == 0x201) cws.push_back(get_u16(s.sent[i].f.data));
  auto edge = std::find(cws.begin(), cws.end(), uint16_t{0x80});
  REQUIRE(edge != cws.end());
  REQUIRE(edge != cws.begin());
  CHECK(*(edge - 1) == 0x00);                              // the rising edge
  CHECK(std::count(cws.begin(), cws.end(), uint16_t{0x80}) == 1);
  CHECK(s.rig.drive(0).state() == cia402::State::SwitchOnDisabled);
  CHECK_FALSE(s.set.faulted());
  CHECK_FALSE(s.enable());
  CHECK(s.rig.drive(0).state() == cia402::State::OperationEnabled);
}

TEST_CASE("canopen: if the master dies the drives stop by themselves") {
  SECTION("SYNC loss: alarm after 2 missed SYNC periods") {
    Session s(kTwoBuses);
    s.start();
    for (int i = 0; i < 40; ++i) s.cycle(Vec2(5, 5));
    int64_t last_sync = 0;
    for (const auto& x : s.sent) if (x.f.id == 0x080 && x.bus == 0) last_sync = x.t_us;
    int64_t t_fault = -1;
    for (int i = 0; i < 40 && t_fault < 0; ++i) {
      s.rig.tick();  // the master is gone: no read/write
      if (s.rig.drive(0).state() == cia402::State::Fault) t_fault = s.rig.now();
    }
    REQUIRE(t_fault > 0);
    // The drive receives the last SYNC one tick (250 us) after it was sent,
    // alarms once 2.5 periods have passed, seen at its next 250 us step.
    CHECK(t_fault - last_sync <= 250 + 2 * 500 + 250 + 250);
    CHECK(t_fault - last_sync > 2 * 500);
    s.rig.tick();
    CHECK(s.rig.drive(0).applied_force_n() == 0.0);
  }
  SECTION("heartbeat consumer 0x1016 (SYNC monitoring off)") {
    Session s(kTwoBuses, [](SimDriveParams& p) { p.sync_loss_limit = 0; });
    s.start();
    for (int i = 0; i < 40; ++i) s.cycle(Vec2(5, 5));
    const int64_t t0 = s.rig.now();
    int64_t t_fault = -1;
    for (int i = 0; i < 1000 && t_fault < 0; ++i) {
      s.rig.tick();
      if (s.rig.drive(1).state() == cia402::State::Fault) t_fault = s.rig.now();
    }
    REQUIRE(t_fault > 0);
    CHECK(t_fault - t0 <= 100000 + 250);  // 0x1016 consumer time 100 ms
    CHECK(t_fault - t0 >= 100000 - 20000 - 250);  // master heartbeat every 20 ms
  }
}

TEST_CASE("canopen: remap outside pre-operational is refused (0x06040041) - the master remaps drives left operational") {
  // Direct SDO client against a simulated drive that is operational.
  SimDriveParams p;
  SimulatedDrive d(p);
  FrameBuffer tx;
  d.process(0, {}, tx);
  d.process(p.boot_delay_us, {}, tx);
  REQUIRE(d.nmt_state() == NmtState::PreOperational);
  const CanFrame start = nmt_frame(NmtCommand::Start, 1);
  d.process(p.boot_delay_us + 1, std::span<const CanFrame>(&start, 1), tx);
  REQUIRE(d.nmt_state() == NmtState::Operational);
  SdoClient c;
  c.set_node(1);
  FrameBuffer req, ans;
  c.download_u32(0, 0x1600, 0, 0, 1, req);
  d.process(p.boot_delay_us + 2, req.span(), ans);
  REQUIRE(ans.size() >= 1);
  FrameBuffer dummy;
  for (const auto& f : ans) c.on_frame(1, f, dummy);
  CHECK(c.error().code == ErrorCode::SdoAbort);
  CHECK(c.error().value == 0x06040041u);

  // A new master (e.g. manip_rt restarted) finds the drives operational.
  Session s(kTwoBuses);
  s.start();
  for (int i = 0; i < 20; ++i) s.cycle();
  CanDriveSet second(s.cfg, s.rig.master_ports());
  s.set = std::move(second);
  const Error e = s.configure();
  INFO(describe(e));
  CHECK_FALSE(e);
}

TEST_CASE("canopen: configured PDO rates that the bus cannot carry are detected, not assumed") {
  // Shared bus at 4 kHz SYNC: 475 bits per 250-bit period. The budget
  // refuses it; with the check bypassed (limit lifted in code, not possible
  // from YAML) the master starts, and the TPDO monitor trips within a few
  // SYNC periods instead of running at a silently lower rate.
  auto cfg = parse_ok(kSharedBus);
  cfg.master.sync_period_us = 250;
  cfg.master.tpdo_miss_limit = 2;
  CHECK(compute_budgets(cfg)[0].load == Approx((475.0 * 4000 + 2600 + 3250 + 2700) / 1e6));  // 190.9 %
  cfg.master.max_bus_load = 2.0;
  Session s(cfg);
  REQUIRE_FALSE(s.configure());
  const Error e = s.enable();
  CHECK(e.code == ErrorCode::TpdoMissing);
  CHECK(s.set.master(0).syncs_sent() < 20u);
  CHECK(s.rig.drive(0).state() != cia402::State::OperationEnabled);
}

TEST_CASE("canopen: CST on the simulated moving mass follows F = m a") {
  Session s(kTwoBuses, [](SimDriveParams& p) {
    p.viscous_nspm = 0;
    p.coulomb_n = 0;
    p.mass_kg = 2.0;
  });
  s.start();
  const double v0 = s.rig.drive(0).velocity_mps();
  for (int i = 0; i < 400; ++i) s.cycle(Vec2(10.0, 0.0));  // 0.1 s
  // 10 N on 2 kg for 0.1 s (minus the command latency of < 1 ms)
  CHECK(s.rig.drive(0).velocity_mps() - v0 == Approx(0.5).epsilon(0.01));
  const auto& fb = s.cycle(Vec2(10.0, 0.0));
  CHECK(fb.velocity_mps.x() == Approx(0.5).epsilon(0.02));
  CHECK(fb.position_m.x() == Approx(0.025).epsilon(0.03));  // 1/2 a t^2
}

TEST_CASE("canopen: TPDOs delayed by the drive within one SYNC period are tolerated, and the feedback lags") {
  Session s(kTwoBuses, [](SimDriveParams& p) {
    p.viscous_nspm = 0;
    p.coulomb_n = 0;
  });
  s.start();
  s.rig.drive(0).faults().tpdo_delay_us = 300;  // 250 us cycle + 300 us: next cycle but one
  Session ref(kTwoBuses, [](SimDriveParams& p) {
    p.viscous_nspm = 0;
    p.coulomb_n = 0;
  });
  ref.start();
  DriveSetFeedback a, b;
  for (int i = 0; i < 2000; ++i) {
    a = s.cycle(Vec2(2.0, 0.0));
    b = ref.cycle(Vec2(2.0, 0.0));
  }
  CHECK_FALSE(s.set.faulted());
  CHECK(s.set.master(0).node(0).tpdo_missed_total == 1u);  // the one period in which the delay began
  // Same motion; the delayed feedback is one SYNC period (500 us) older.
  CHECK(b.position_m.x() > a.position_m.x());
  CHECK(b.position_m.x() - a.position_m.x() == Approx(b.velocity_mps.x() * 500e-6).epsilon(0.05));
}

namespace {
// A port that starts refusing frames (full transmit queue, interface down).
struct FlakyPort : CanPort {
  CanPort* inner;
  bool refuse = false;
  explicit FlakyPort(CanPort* p) : inner(p) {}
  bool send(const CanFrame& f) override { return refuse ? false : inner->send(f); }
  std::size_t receive(std::span<CanFrame> out) override { return inner->receive(out); }
};
}  // namespace

TEST_CASE("canopen fault: the transport refuses frames") {
  auto cfg = parse_ok(kTwoBuses);
  VirtualRig rig(cfg);
  auto ports = rig.master_ports();
  FlakyPort flaky(ports[0]);
  ports[0] = &flaky;
  CanDriveSet set(cfg, ports);
  auto tick = [&] { return rig.tick(); };
  REQUIRE_FALSE(set.configure(tick));
  REQUIRE_FALSE(set.enable(tick));
  flaky.refuse = true;
  int n = 0;
  for (; n < 10 && !set.faulted(); ++n) {
    const int64_t t = rig.tick();
    set.read(t);
    set.write(Vec2(1, 1));
  }
  CHECK(n <= 3);  // next SYNC (<= 2 cycles) is refused, seen at the following read()
  CHECK(set.error().code == ErrorCode::TxOverflow);
  CHECK(describe(set.error()) == "bus: transmit queue overflow");
  for (int i = 0; i < 4; ++i) rig.tick();
  CHECK(rig.drive(1).state() != cia402::State::OperationEnabled);  // the other bus went safe
}
