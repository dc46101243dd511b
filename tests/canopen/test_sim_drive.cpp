// The simulated drive's object dictionary and frames, and a bare Master over
// the virtual bus with Master::poll.
#include <catch2/catch.hpp>

#include "manip/canopen/master.hpp"
#include "manip/canopen/simulated_drive.hpp"
#include "manip/canopen/virtual_bus.hpp"
#include "rig.hpp"

using namespace manip::canopen;

namespace {
struct Bench {
  SimDriveParams p;
  SimulatedDrive d{p};
  int64_t t = 0;
  FrameBuffer out;
  Bench() {
    d.process(0, {}, out);
    t = p.boot_delay_us;
    out.clear();
    d.process(t, {}, out);  // boot-up
  }
  // One SDO request, returns the drive's answer.
  CanFrame ask(const CanFrame& req) {
    out.clear();
    d.process(++t, std::span<const CanFrame>(&req, 1), out);
    for (const auto& f : out)
      if (f.id == 0x581) return f;
    return CanFrame{};
  }
};
uint32_t abort_of(const CanFrame& f) { return f.data[0] == 0x80 ? get_u32(f.data + 4) : 0; }
}  // namespace

TEST_CASE("simulated drive: boot-up message, SDO answers and abort codes of CiA 301") {
  Bench b;
  REQUIRE(b.out.size() == 1);
  CHECK(b.out[0] == make_frame(0x701, {0x00}));  // boot-up
  CHECK(b.ask(sdo::upload_request(1, 0x1000, 0)) == make_frame(0x581, {0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00}));
  CHECK(b.ask(sdo::upload_request(1, 0x6060, 0)) == make_frame(0x581, {0x4F, 0x60, 0x60, 0x00, 0x00, 0, 0, 0}));
  CHECK(abort_of(b.ask(sdo::upload_request(1, 0x1234, 0))) == 0x06020000u);   // no object
  CHECK(abort_of(b.ask(sdo::upload_request(1, 0x1018, 9))) == 0x06090011u);   // no sub-index
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1000, 0, 5, 4))) == 0x06010002u);  // read only
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1017, 0, 5, 4))) == 0x06070012u);  // too long
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x6060, 0, 3, 1))) == 0x06090030u);  // mode 3 not offered
  CHECK(b.ask(sdo::expedited_download(1, 0x1017, 0, 50, 2)) == make_frame(0x581, {0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0}));
  // Remap in pre-operational: PDO still valid -> refused; mapping an object
  // that cannot be mapped (statusword into an RPDO) -> 0x06040041.
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 0, 0, 1))) == 0x08000022u);
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1400, 1, 0x80000201u, 4))) == 0u);
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 1, 0x60400010u, 4))) == 0x08000022u);  // sub0 != 0
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 0, 0, 1))) == 0u);
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 1, 0x60410010u, 4))) == 0x06040041u);
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 1, 0x60710020u, 4))) == 0x06040041u);  // wrong length
  CHECK(abort_of(b.ask(sdo::expedited_download(1, 0x1600, 1, 0x60710010u, 4))) == 0u);
}

TEST_CASE("simulated drive: EMCY frame layout (CiA 301 §7.2.7.3.1) and CST only when enabled") {
  Bench b;
  b.d.inject_emcy(0x3210, 0x05, false, 0x00000004);
  b.out.clear();
  b.d.process(++b.t, {}, b.out);
  REQUIRE(b.out.size() >= 1);
  CHECK(b.out[0] == make_frame(0x081, {0x10, 0x32, 0x05, 0x04, 0x00, 0x00, 0x00, 0x00}));
  CHECK(b.d.od_value(0x1001, 0) == 0x05u);
  CHECK(b.d.od_value(0x1002, 0) == 0x04u);
  // A torque target without Operation enabled moves nothing.
  b.ask(sdo::expedited_download(1, 0x6071, 0, 500, 2));
  for (int i = 0; i < 100; ++i) b.d.process(b.t += 250, {}, b.out);
  CHECK(b.d.position_m() == 0.0);
  CHECK(b.d.applied_force_n() == 0.0);
}

TEST_CASE("canopen master alone (shared bus) with Master::poll: start-up to cyclic") {
  auto cfg = canopen_test::parse_ok(canopen_test::kSharedBus);
  VirtualBus bus;
  auto& mp = bus.attach();
  SimDriveParams p1, p2;
  p1.node_id = 1;
  p2.node_id = 2;
  SimulatedDrive d1(p1), d2(p2);
  auto& e1 = bus.attach();
  auto& e2 = bus.attach();
  Master m(cfg, "can");
  m.start(0);
  int64_t t = 0;
  for (int i = 0; i < 4000 && m.phase() != Phase::Cyclic && m.phase() != Phase::Failed; ++i) {
    t += 250;
    bus.set_time(t);
    d1.poll(t, e1);
    d2.poll(t, e2);
    CHECK(m.poll(t, mp));
  }
  INFO(describe(m.error()));
  REQUIRE(m.phase() == Phase::Cyclic);
  CHECK(m.steps_done() == m.steps_total());
  CHECK(d1.nmt_state() == NmtState::Operational);
  CHECK(d2.nmt_state() == NmtState::Operational);
  const uint32_t s0 = m.syncs_sent();
  for (int i = 0; i < 400; ++i) {
    t += 250;
    bus.set_time(t);
    d1.poll(t, e1);
    d2.poll(t, e2);
    m.poll(t, mp);
  }
  CHECK(m.syncs_sent() - s0 == 100u);  // 1 kHz SYNC on the shared bus
  CHECK(d2.sync_count() >= 100u);
  CHECK(m.node(1).tpdo_missed_total == 0u);
}
