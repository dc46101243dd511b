// manip_can_check's logic against a good and broken simulated set-ups.
#include <catch2/catch.hpp>

#include "manip/canopen/can_check.hpp"
#include "rig.hpp"

using namespace canopen_test;
using namespace manip::canopen;

namespace {
// The simulated drives are built from `sim_cfg` (the real hardware), the
// master from `cfg` (what the operator configured).
CheckResult check(const CanConfig& cfg, const std::function<void(VirtualRig&)>& breakit = {},
                  const CanConfig* sim_cfg = nullptr) {
  VirtualRig rig(sim_cfg ? *sim_cfg : cfg);
  if (breakit) breakit(rig);
  return run_can_check(cfg, rig.master_ports(), [&] { return rig.tick(); }, 400);
}
bool contains(const std::string& s, const std::string& x) { return s.find(x) != std::string::npos; }
}  // namespace

TEST_CASE("canopen can_check: good set-up") {
  const auto r = check(parse_ok(kTwoBuses));
  INFO(r.report);
  CHECK(r.exit_code == kCheckOk);
  CHECK(contains(r.report, "node 1 (stage_x): NMT operational, device type 0x00020192, vendor 0x000000AB"));
  CHECK(contains(r.report, "name 'manip simulated CiA 402 drive', error register 0x00, rated current 5000 mA"));
  CHECK(contains(r.report, "node 1: 400 TPDOs in 400 SYNC periods (100.0 % of the configured rate), 0 missed"));
  CHECK(contains(r.report, "total 535900 bit/s = 53.6 % of the bus (limit 70.0 %): OK"));
  CHECK(contains(r.report, "OK: the bus is ready"));
}

TEST_CASE("canopen can_check: broken set-ups exit non-zero with a readable reason") {
  auto cfg = parse_ok(kTwoBuses);
  SECTION("over budget (shared bus at 2 kHz)") {
    auto shared = parse_ok(kSharedBus);
    shared.master.sync_period_us = 500;
    const auto r = check(shared);
    CHECK(r.exit_code == kCheckBudget);
    CHECK(contains(r.report, "95.9 % of the bus (limit 70.0 %): REFUSED"));
  }
  SECTION("a drive that never boots") {
    const auto r = check(cfg, [](VirtualRig& rig) { rig.drive(1).faults().never_boot = true; });
    CHECK(r.exit_code == kCheckDrive);
    CHECK(contains(r.report, "FAIL: node 1: node never booted"));
  }
  SECTION("wrong vendor (another drive on the node id)") {
    auto configured = cfg;
    configured.drives[0].vendor_id = 0x0000009A;
    const auto r = check(configured, {}, &cfg);
    CHECK(r.exit_code == kCheckDrive);
    CHECK(contains(r.report, "FAIL: node 1: read-back differs from the configuration at 0x1018:01: read 0x000000AB, expected 0x0000009A"));
  }
  SECTION("drive refuses the PDO mapping") {
    const auto r = check(cfg, [](VirtualRig& rig) {
      rig.drive(0).faults().reject_index = 0x1A00;
      rig.drive(0).faults().reject_sub = 2;
      rig.drive(0).faults().reject_abort = 0x06040041;
    });
    CHECK(r.exit_code == kCheckDrive);
    CHECK(contains(r.report, "FAIL: node 1: SDO aborted by the drive at 0x1A00:02, abort code 0x06040041 (object cannot be mapped"));
  }
  SECTION("TPDOs lost on the bus (rate not achieved)") {
    const auto r = check(cfg, [](VirtualRig& rig) {
      int n = 0;
      rig.bus(0).set_injector([n](int, const CanFrame& f) mutable {
        return VirtualBus::Injection{f.id == 0x181 && (++n % 50) == 0, 0};
      });
    });
    CHECK(r.exit_code == kCheckDrive);
    CHECK(contains(r.report, "(98.0 % of the configured rate), 8 missed"));
    CHECK(contains(r.report, "FAIL: configured PDO rate not achieved"));
  }
}
