#include <catch2/catch.hpp>

#include "manip/canopen/config.hpp"
#include "config_errors.hpp"
#include "rig.hpp"

using namespace manip::canopen;

using canopen_test::errors_of;
using canopen_test::has;

TEST_CASE("canopen config: a valid bus.yml") {
  const auto c = canopen_test::parse_ok(canopen_test::kTwoBuses);
  REQUIRE(c.buses.size() == 2);
  CHECK(c.buses[1].interface == "can1");
  REQUIRE(c.drives.size() == 2);
  CHECK(c.drives[1].name == "stage_y");
  CHECK(c.drives[1].sign == -1);
  CHECK(c.drives[1].workspace_axis == 1);
  CHECK(c.drives[0].vendor_id == 0xABu);
  CHECK(c.drives[0].rated_force_n() == Approx(100.0));
  CHECK(c.master.sync_period_us == 500u);
  CHECK(c.drives[0].rpdo.bytes() == 4);
  CHECK(c.drives[0].tpdo.bytes() == 6);
}

TEST_CASE("canopen config: unknown keys, wrong types, ranges and cross checks with file:line") {
  std::string t = canopen_test::kTwoBuses;
  SECTION("unknown key") {
    t.replace(t.find("    sign: 1\n"), 12, "    sigm: 1\n");
    CHECK(has(errors_of(t), "bus.yml:26: nodes.stage_x.sigm: unknown key"));
  }
  SECTION("wrong type") {
    t.replace(t.find("500"), 3, "fast");
    CHECK(has(errors_of(t), "bus.yml:3: master.sync_period_us: expected an integer, got 'fast'"));
  }
  SECTION("out of range") {
    t.replace(t.find("node_id: 127"), 12, "node_id: 300");
    CHECK(has(errors_of(t), "bus.yml:2: master.node_id: value 300 out of range [1, 127]"));
  }
  SECTION("unknown bus and duplicate axis") {
    t.replace(t.find("bus: bus_y"), 10, "bus: bus_z");
    t.replace(t.find("workspace_axis: 1"), 17, "workspace_axis: 0");
    const auto e = errors_of(t);
    CHECK(has(e, "bus.yml:28: nodes.stage_y.bus: unknown bus 'bus_z'"));
    CHECK(has(e, "bus.yml:28: nodes.stage_y.workspace_axis: axis 0 already driven by stage_x"));
  }
  SECTION("PDO too long, unknown object") {
    t += "    tpdo: [statusword, position_actual, velocity_actual]\n";
    CHECK(has(errors_of(t), "bus.yml:32: nodes.stage_y.tpdo: mapping needs 10 bytes, a CAN PDO carries at most 8"));
    std::string u = canopen_test::kTwoBuses;
    u += "    rpdo: [controlword, target_velocity]\n";
    CHECK(has(errors_of(u), "bus.yml:32: nodes.stage_y.rpdo: unknown RPDO object 'target_velocity' (allowed: controlword, target_torque)"));
  }
  SECTION("heartbeat timeout must exceed the producer time; sign must be +-1") {
    t.replace(t.find("heartbeat_timeout_ms: 150"), 25, "heartbeat_timeout_ms: 40");
    t.replace(t.find("sign: -1"), 8, "sign: 0");
    const auto e = errors_of(t);
    CHECK(has(e, "bus.yml:23: nodes.stage_x.heartbeat_timeout_ms: must exceed heartbeat_producer_ms"));
    CHECK(has(e, "bus.yml:31: nodes.stage_y.sign: must be +1 or -1"));
  }
  SECTION("the e-stop input on 0x60FD must be mapped in every drive's TPDOs") {
    t += "backend:\n  estop_input_bit: 16\n";
    t.replace(t.find("    sign: -1\n"), 13, "    sign: -1\n    tpdo2: [digital_inputs]\n");
    const auto e = errors_of(t);
    CHECK(has(e, "bus.yml:23: nodes.stage_x.tpdo2: backend.estop_input_bit needs digital_inputs (0x60FD) mapped in tpdo or tpdo2 of every drive"));
    for (const auto& x : e) CHECK(x.find("stage_y") == std::string::npos);  // stage_y maps it
    std::string u = canopen_test::kTwoBuses;
    u += "backend:\n  estop_input_bit: 32\n";
    CHECK(has(errors_of(u), "bus.yml:33: backend.estop_input_bit: value 32 out of range [-1, 31]"));
  }
  SECTION("missing file") {
    CanConfig c;
    std::vector<std::string> e;
    CHECK_FALSE(load_config("/nonexistent/bus.yml", c, e));
    CHECK(has(e, "/nonexistent/bus.yml:0: <file>: cannot open"));
  }
}

TEST_CASE("canopen units: counts <-> metres, newtons <-> per mille, signs, saturation") {
  auto c = canopen_test::parse_ok(canopen_test::kTwoBuses);
  const AxisScaling x = AxisScaling::from(c.drives[0]);
  const AxisScaling y = AxisScaling::from(c.drives[1]);
  CHECK(x.position_m(150000) == Approx(0.15));
  CHECK(y.position_m(150000) == Approx(-0.15));
  // 10 N of 100 N rated (5 A * 20 N/A) = 100 per mille; the y drive pushes the other way.
  CHECK(x.torque_permille(10.0) == 100);
  CHECK(y.torque_permille(10.0) == -100);
  CHECK(x.force_n(100) == Approx(10.0));
  CHECK(y.force_n(-100) == Approx(10.0));
  c.drives[0].max_torque_permille = 500;
  const AxisScaling s = AxisScaling::from(c.drives[0]);
  CHECK(s.torque_permille(60.0) == 500);
  CHECK(s.torque_permille(-1e9) == -500);
  CHECK(s.torque_permille(std::nan("")) == 0);
  c.drives[0].velocity_units_per_count_s = 10;  // Copley: 0.1 count/s
  CHECK(AxisScaling::from(c.drives[0]).velocity_mps(10000) == Approx(0.001));
}

TEST_CASE("canopen config: the shipped example tests/canopen/bus.yml") {
  CanConfig c;
  std::vector<std::string> e;
  REQUIRE(load_config(std::string(MANIP_SOURCE_DIR) + "/tests/canopen/bus.yml", c, e));
  CHECK(c.drives.size() == 2);
  CHECK(c.drives[1].max_torque_permille == 800u);
  CHECK(c.drives[0].abort_connection_option == 1);
}

TEST_CASE("canopen config: hostile YAML is refused, never thrown (found by fuzz_can_config)") {
  // A mapping used as a key made yaml-cpp's as<std::string>() throw through
  // parse_config; a duplicate key was silently resolved to its first value.
  const std::string mapping_key = "master:\n  ? {a: 1}\n  : 2\n";
  const auto e1 = errors_of(mapping_key);
  REQUIRE(!e1.empty());
  CHECK(e1[0].rfind("bus.yml:", 0) == 0);
  const auto e2 = errors_of("master:\n  node_id: 1\n  node_id: 2\n");
  REQUIRE(!e2.empty());
  CHECK(e2[0] == "bus.yml:3: master.node_id: duplicate key (given twice in one mapping)");
}
