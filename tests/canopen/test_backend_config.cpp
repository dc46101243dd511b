// The `backend:` section of the CANopen configuration (the can backend's
// safety inputs, force sensor and --can-virtual): strict like the rest.
#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>

#include "manip/canopen/bus_load.hpp"
#include "manip/canopen/config.hpp"
#include "config_errors.hpp"
#include "rig.hpp"

using namespace manip::canopen;

using canopen_test::errors_of;
using canopen_test::has;

TEST_CASE("canopen config: backend section defaults and values", "[config]") {
  const CanConfig d = canopen_test::parse_ok(canopen_test::kTwoBuses);
  CHECK_FALSE(d.backend.virtual_bus);
  CHECK(d.backend.estop_statusword_bit == -1);
  CHECK(d.backend.force_sensor == "sim");
  const CanConfig c = canopen_test::parse_ok(std::string(canopen_test::kTwoBuses) +
                                             "backend:\n  virtual: true\n  estop_statusword_bit: 14\n"
                                             "  force_sensor: netft\n  netft_port: 50000\n  sensor_rotation_deg: -45\n");
  CHECK(c.backend.virtual_bus);
  CHECK(c.backend.estop_statusword_bit == 14);
  CHECK(c.backend.force_sensor == "netft");
  CHECK(c.backend.netft_port == 50000u);
  CHECK(c.backend.sensor_rotation_deg == -45.0);
}

TEST_CASE("canopen config: backend section errors carry file, line and key", "[config]") {
  const std::string base = canopen_test::kTwoBuses;  // 31 lines
  const auto e = errors_of(base + "backend:\n  virtul: true\n  estop_statusword_bit: 3\n  force_sensor: jr5\n");
  CHECK(has(e, "bus.yml:33: backend.virtul: unknown key"));
  CHECK(has(e, "bus.yml:34: backend.estop_statusword_bit: must be -1 (not wired) or a manufacturer-specific statusword bit (8, 14, 15)"));
  CHECK(has(e, "bus.yml:35: backend.force_sensor: expected sim, netft, jr3 or none"));
}

TEST_CASE("canopen config: the shipped config/can.yaml is valid and fits its budget", "[config]") {
  CanConfig c;
  std::vector<std::string> e;
  REQUIRE(load_config(std::string(MANIP_SOURCE_DIR) + "/config/can.yaml", c, e));
  CHECK(c.buses.size() == 2);
  CHECK(c.master.sync_period_us == 500u);
  CHECK_FALSE(c.backend.virtual_bus);
  for (const auto& b : compute_budgets(c)) {
    CHECK(b.ok());
    // hand count per SYNC period: SYNC 55 + RPDO1 (4 B) 95 + TPDO1 (6 B) 115 + TPDO2 (4 B) 95
    CHECK(b.cyclic_bits_per_sync == 55 + 95 + 115 + 95);
  }
}
